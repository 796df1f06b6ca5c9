"""Curvature traces on the km of the surveyed balises: samples, coverage, mean profiles.

Each κ sample of a run (:mod:`fieldlogs.survey.extract`) is placed through its chain's
trajectory (:mod:`fieldlogs.survey.trajectory`) at

    km = km(c(x)) − σ·cab·x_r

(the reader's km moved back to the vehicle's reference point, which the feature rows refer
to: :mod:`fieldlogs.pipeline.geometry`) and turned into the curvature in the track's normal
running direction, corrected for the wheel's scale:

    κ_n = κ·σ·s_track / λ

(κ = ωz/v is left-positive in the travel direction; s_track = +1 on D/S, −1 on U; v from
the configured wheel is 1/λ times the true speed, so κ is λ times the true curvature).
A *pass* is one run's chain over the track (one segment: a run that comes back over a
track after a reversal passes it twice). Per track the samples are averaged per
``profile_bin_m`` bin, first within a pass, then over passes: the mean profile κ̄(km) and
the number of passes per bin.

**Tracks off every line** (a network track with no line km, :mod:`fieldlogs.survey.extract`
keeps its place as ``pos_m``, the distance from the track's begin): no balise chain reaches
them (their balises carry no line km), so a segment there is placed by dead reckoning from
the pipeline's position at its first cycle, with the run's wheel scale:

    pos(x) = pos₀ + σ·λ·(x − d₀)

(pos₀, d₀ the segment's place and travel at its first cycle, σ its motion, λ the run's
wheel scale — the travel is 1/λ times the true distance). Starting from the first cycle,
not interpolating to the last, keeps the pipeline's own curve correction (which a
``track_feature_points`` feature applies at its exit) out of the place of that curve.
Such a track is keyed ``("", track_id)`` and its normal running direction is the one of
``pos_m`` increasing (as ``track_feature_points`` are written): κ_n = κ·σ/λ.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.metric import track_metric
from fieldlogs.survey.extract import RunSurvey
from fieldlogs.survey.trajectory import Trajectory
from schemas.enums import direction_sign

FloatArray = npt.NDArray[np.float64]
TrackKey = tuple[str, str]
"""(line_code, track) along a line; ("", track_id) on a track off every line."""
#: Pass id = run index × this + segment.
PASS_BASE = 100_000


@dataclass(frozen=True)
class TrackSamples:
    """κ samples of one line/track from every pass, sorted by km."""

    pass_id: npt.NDArray[np.int64]
    """run index × :data:`PASS_BASE` + segment."""
    km: FloatArray
    kappa: FloatArray
    """κ_n [1/m] (module docstring)."""

    def window(self, lo: float, hi: float) -> slice:
        """Samples with lo ≤ km ≤ hi (``km`` is sorted)."""
        return slice(int(np.searchsorted(self.km, lo, "left")), int(np.searchsorted(self.km, hi, "right")))


@dataclass(frozen=True)
class Coverage:
    """km intervals with a usable κ, per pass (one line/track)."""

    pass_id: npt.NDArray[np.int64]
    lo: FloatArray
    hi: FloatArray

    def passes_covering(self, lo: float, hi: float) -> set[int]:
        """Passes whose usable κ covers [lo, hi] entirely."""
        ok = (self.lo <= lo) & (self.hi >= hi)
        return {int(r) for r in self.pass_id[ok]}


Parts = dict[TrackKey, list[tuple[int, FloatArray, FloatArray]]]


def place_samples(
    runs: Sequence[RunSurvey], traj: dict[tuple[int, int], Trajectory], scale: FloatArray, network: Network
) -> tuple[dict[TrackKey, TrackSamples], dict[TrackKey, Coverage]]:
    """Every run's κ samples and coverage on the km of its chains (module docstring)."""
    parts: Parts = {}
    cov: Parts = {}
    for r, rs in enumerate(runs):
        lam = float(scale[r]) if np.isfinite(scale[r]) else 1.0
        sg = rs.segments
        k_seg = rs.kappa["seg"].to_numpy(dtype=np.int64)
        k_x, k_v = rs.kappa["x_m"].to_numpy(dtype=float), rs.kappa["kappa"].to_numpy(dtype=float)
        c_seg = rs.coverage["seg"].to_numpy(dtype=np.int64)
        c_x0, c_x1 = rs.coverage["x0_m"].to_numpy(dtype=float), rs.coverage["x1_m"].to_numpy(dtype=float)
        for g in sg.to_dict("records"):
            seg = int(g["seg"])
            placed = _placement(network, g, traj.get((r, seg)), lam, rs.reader_x_m)
            if placed is None:
                continue
            key, to_km, sign, (reach_lo, reach_hi) = placed
            sel = k_seg == seg
            km = to_km(k_x[sel])
            kn = k_v[sel] * sign / lam
            ok = np.isfinite(km)
            parts.setdefault(key, []).append((r * PASS_BASE + seg, km[ok], kn[ok]))
            sel = c_seg == seg
            a = to_km(np.clip(c_x0[sel], reach_lo, reach_hi))
            b = to_km(np.clip(c_x1[sel], reach_lo, reach_hi))
            cov.setdefault(key, []).append((r * PASS_BASE + seg, np.fmin(a, b), np.fmax(a, b)))
    return {k: _samples(v) for k, v in parts.items()}, {k: _coverage(v) for k, v in cov.items()}


Placement = tuple[TrackKey, Callable[[FloatArray], FloatArray], int, tuple[float, float]]


def _placement(
    network: Network, seg: Mapping[Any, Any], tj: Trajectory | None, lam: float, reader_x_m: float
) -> Placement | None:
    """Key, travel → place, σ·s_track and the travel reach of one segment (module docstring);
    None where it cannot be placed (a line segment without a chain, no motion)."""
    line, track, tid = (str(seg[c]) if pd.notna(seg[c]) else "" for c in ("line_code", "track", "track_id"))
    if not line:
        motion = int(seg["motion"])
        if not tid or motion == 0:
            return None
        pos0, d0 = float(seg["km0_m"]), float(seg["d0_m"])

        def to_pos(x: FloatArray) -> FloatArray:
            return np.asarray(pos0 + motion * lam * (x - d0), dtype=float)

        return ("", tid), to_pos, motion, (d0, float(seg["d1_m"]))
    if tj is None:
        return None
    key = (line, track)
    to_km = _to_km(network, key, tj, int(seg["cab"]), reader_x_m)
    return key, to_km, tj.motion * direction_sign(track), (tj.d[0] - tj.reach_m, tj.d[-1] + tj.reach_m)


def _to_km(
    network: Network, key: TrackKey, tj: Trajectory, cab: int, reader_x_m: float
) -> Callable[[FloatArray], FloatArray]:
    """Travel → the reference point's km on one chain (module docstring)."""
    metric = track_metric(network, key[0], key[1])
    shift = tj.motion * cab * reader_x_m

    def to_km(x: FloatArray) -> FloatArray:
        return np.asarray(metric.km_of_c(tj.c_at(x)) - shift, dtype=float)

    return to_km


def _samples(parts: list[tuple[int, FloatArray, FloatArray]]) -> TrackSamples:
    """The parts as one :class:`TrackSamples`, sorted by km (then pass)."""
    pid = np.concatenate([np.full(p[1].size, p[0], dtype=np.int64) for p in parts])
    km = np.concatenate([p[1] for p in parts])
    order = np.lexsort((pid, km))
    return TrackSamples(pid[order], km[order], np.concatenate([p[2] for p in parts])[order])


def _coverage(parts: list[tuple[int, FloatArray, FloatArray]]) -> Coverage:
    pid = np.concatenate([np.full(p[1].size, p[0], dtype=np.int64) for p in parts])
    return Coverage(pid, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]))


def mean_profile(s: TrackSamples, bin_m: float) -> pd.DataFrame:
    """km (bin centre), kappa (mean over passes of the passes' bin means), passes — sorted by km."""
    b = np.floor(s.km / bin_m).astype(np.int64)
    per_pass = (
        pd.DataFrame({"bin": b, "pass": s.pass_id, "k": s.kappa}).groupby(["bin", "pass"], sort=False)["k"].mean()
    )
    prof = per_pass.groupby(level="bin").agg(["mean", "size"]).sort_index()
    return pd.DataFrame(
        {
            "km_m": (prof.index.to_numpy(dtype=float) + 0.5) * bin_m,
            "kappa": prof["mean"].to_numpy(dtype=float),
            "passes": prof["size"].to_numpy(dtype=np.int64),
        }
    )
