"""Is ``radar_if`` in the I/Q convention run.json declares? [S004 §2, eq. 1]

A recorder whose quadrature channel has the other sign (``i-jq``: z = I − jQ, a common
wiring) gives the complex conjugate of the IF signal the chain assumes. Conjugation
mirrors both things a ground line is made of: its Doppler, f_d → −f_d, and the f1–f2 phase
difference, Δφ → −Δφ, so its range R = c·Δφ/(4π·Δf) becomes Rmax − R (Rmax = c/(2·Δf)).
With the ground at h/sin θ ≈ 1 m and Rmax = 11.76 m (Table 1) the mirrored range is nowhere
near the ground, so every moving frame comes out ``no_reflections`` — silently.

The test needs no other sensor (a tacho's direction would tell the Doppler side only, and a
radar looking backwards flips that too): a sample of frames spread over the run is
processed as declared and conjugated; when the conjugated samples give ground lines that
fit eq. 1 (status ``ok``) in at least ``MIN_FRAMES`` frames and in more than
``MARGIN`` times as many frames as the declared ones, the other convention is named. Correct
samples conjugated put every line near Rmax − R (or, aliased, Rmax/2 − R): never ``ok``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.framing import Frames
from fieldlogs.radar.speed import process_frames
from schemas.enums import IqConvention, RadarStatus, Severity
from schemas.findings import Finding
from schemas.radar import RadarParams

#: Frames sampled from the run (evenly spread) for the test.
SAMPLE_FRAMES = 64
#: Conjugated ``ok`` frames needed before the other convention is named …
MIN_FRAMES = 3
#: … and how many times the declared convention's ``ok`` frames they must outnumber.
MARGIN = 2


@dataclass(frozen=True)
class ConventionCheck:
    """``ok`` frames of the sample as declared and conjugated, and the convention they point to."""

    sampled: int
    ok_declared: int
    ok_conjugated: int
    declared: str

    @property
    def mismatch(self) -> bool:
        return self.ok_conjugated >= max(MIN_FRAMES, MARGIN * self.ok_declared + 1)

    @property
    def other(self) -> str:
        plus, minus = IqConvention.I_PLUS_JQ.value, IqConvention.I_MINUS_JQ.value
        return minus if self.declared == plus else plus


def _sample(frames: Frames, n: int) -> Frames:
    """Up to ``n`` frames spread evenly over the run (a copy; ``present`` kept)."""
    k = np.unique(np.linspace(0, frames.n_frames - 1, min(n, frames.n_frames)).round().astype(np.int64))
    present = None if frames.present is None else frames.present[k]
    return Frames(frames.i1[k], frames.q1[k], frames.i2[k], frames.q2[k], present, frames.t_first, frames.rate_hz)


def check_convention(frames: Frames, params: RadarParams, cfg: RadarConfig = RadarConfig()) -> ConventionCheck:
    """Process a sample of ``frames`` (already in the declared convention) as they are and
    conjugated (q → −q of both frequencies) and count the ``ok`` frames of each."""
    if frames.n_frames == 0:
        return ConventionCheck(0, 0, 0, params.iq_convention)
    s = _sample(frames, SAMPLE_FRAMES)
    mirrored = replace(s, q1=-s.q1, q2=-s.q2)
    ok = RadarStatus.OK.value
    n_decl = int((process_frames(s, params, cfg).columns["status"] == ok).sum())
    n_conj = int((process_frames(mirrored, params, cfg).columns["status"] == ok).sum())
    return ConventionCheck(s.n_frames, n_decl, n_conj, params.iq_convention)


def convention_finding(check: ConventionCheck, file: str) -> Finding | None:
    """A warning naming the stream and the declaration to add, when the samples look conjugated."""
    if not check.mismatch:
        return None
    return Finding(
        "radar.iq_convention",
        Severity.WARNING,
        "radar_if",
        f"radar_if looks recorded with the other I/Q sign convention: of {check.sampled} sampled frames "
        f"{check.ok_conjugated} give ground lines that fit S004 eq. 1 with Q negated, {check.ok_declared} as "
        f"declared ({check.declared}) — the rest read as no_reflections. Declare "
        f'"iq_convention": "{check.other}" in run.json\'s radar block',
        file=file,
        column="radar.iq_convention",
        value=check.declared,
        limit=check.other,
    )
