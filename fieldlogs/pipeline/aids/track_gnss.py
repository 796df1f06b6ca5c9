"""Raw GNSS fits constrained to each candidate track as an aid [SPEC §8.3; S002].

The track-constrained pseudorange fit (:mod:`fieldlogs.gnss.ontrack`) holds the antenna on a
given track; on the wrong track the fit leaves large residuals: a track d metres to the side
shifts each range by d·cos E·sin(A − ψ), of which the clock and the along-track position absorb
only the common and along-track parts (4 m between D and U of the network sample: residual RMS
1.6 m against 0.7 m on the right track in open sky, 2.9 m against 1.4 m beside buildings;
tests/fieldlogs/pipeline/test_network_raw_gnss.py).
Each candidate is fitted on its own polyline: a line track of the GIS grid by (line, track,
facing by the sign of its km per forward metre), a track off the grid — a station track or a
crossover — on its ``track_points`` (:func:`fieldlogs.gnss.gis.points_track`, facing by the
sign of its pos per forward metre); the solver marks epochs beyond a short track's ends off
track, so they are not compared. While the estimate is ambiguous, at each GNSS epoch the
candidates are compared pairwise.

Per epoch i where both a and b have a fit from the same satellites with redundancy
(:class:`fieldlogs.gnss.ontrack.TrackEvidence`), e_i = T_a,i − T_b,i, T = Σ v²/σ² the fit's
test statistic summed over the receivers: under the solver's Gaussian error model e_i is twice
the log-likelihood ratio of b over a [S002]. Over the epochs since the split (at most
``gnss.track_window_s``; n of them), a is dropped when

    n ≥ N,   N · median(e) > χ²,   #{e_i > 0} / n ≥ share,

N = ``gnss.split_epochs``, χ² = ``gnss.track_chi2`` (χ²₁ at 10⁻³), share = ``gnss.track_share``.
N · median(e) is the log-likelihood sum of N epochs with the median in place of the mean, so
that a few epochs of multipath or a reflected signal cannot carry it; no more than N epochs are
counted however long the window, because the errors that move a fit across the track (multipath,
orbit and atmosphere) stay correlated over tens of seconds. The share is a sign test: the epochs
at the toe, where the branches still coincide, favour either at random and hold the decision
back until the branches have parted. Measured on the simulator's pseudoranges (G, E, J; two
receivers), 4 m apart: e ≈ 5–17 per epoch. The line aid's test (:mod:`.gnss`:
``gnss.track_min_epochs`` epochs, the median itself above χ²) is stricter: it only reports a
disagreement along a whole line, while after a facing switch the branch may be short (80 m
between the crossovers of the network sample) and one of the candidates is the true track.
Event evidence: ``track_gnss``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from fieldlogs.gnss.config import GnssConfig
from fieldlogs.gnss.ontrack import TrackEvidence, TrackSolutions
from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.aids.track_imu import resolve
from fieldlogs.pipeline.hypotheses import TrackLines
from fieldlogs.pipeline.types import Fix, FloatArray

Key = tuple[str, str, int]


class Solver(Protocol):
    """What the aid needs of :class:`fieldlogs.pipeline.aids.gnss.GnssUnit`."""

    def solutions(self, line_code: str, track: str, direction: int) -> Any: ...


@dataclass(eq=False)
class TrackGnssAid:
    """Pairwise constrained-fit test between the candidates (module docstring)."""

    unit: Solver
    epochs: FloatArray
    """Epoch times, in order."""
    lines: TrackLines
    cfg: GnssConfig
    name: str = "track_gnss"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    _pairs: dict[tuple[Key, Key], TrackEvidence] = field(default_factory=dict)

    def observations(self) -> list[Observation]:
        return []

    def keys(self, fix: Fix) -> list[Key] | None:
        """The polyline and facing of each candidate: (line, track, facing by km) on a line
        track of the grid, ("", track id, facing by pos) on a track of ``track_points`` (a
        station or crossover track); None when two share one."""
        out = []
        for h in fix.hyps:
            tl = self.lines[h.track_id]
            if tl.metric is not None:
                out.append((tl.line_code, tl.track, 1 if h.kp * tl.km_sign >= 0 else -1))
            else:
                out.append(("", tl.track_id, 1 if h.kp >= 0 else -1))
        return out if len(set(out)) == len(out) > 1 else None

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or self.keys(fix) is None:
            return None
        j = int(np.searchsorted(self.epochs, view.t, side="right"))
        return Observation(float(self.epochs[j])) if j < self.epochs.size else None

    def _evidence(self, a: Key, b: Key) -> TrackEvidence | None:
        if (a, b) not in self._pairs:
            sa, sb = self.unit.solutions(*a), self.unit.solutions(*b)
            if not isinstance(sa, TrackSolutions) or not isinstance(sb, TrackSolutions):
                return None
            self._pairs[(a, b)] = TrackEvidence.between(sa, sb)
        return self._pairs[(a, b)]

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        keys = None if fix is None else self.keys(fix)
        if fix is None or keys is None:
            return Outcome()
        split = [h.split_d for h in fix.hyps if h.split_d is not None]
        t_split = (
            float(np.interp(max(split), view.travel.d, view.travel.t)) if split else view.t - self.cfg.track_window_s
        )
        window = min(self.cfg.track_window_s, view.t - t_split)
        c = self.cfg
        drop = set()
        for i, a in enumerate(keys):
            for b in keys:
                ev = None if a == b else self._evidence(a, b)
                n = c.split_epochs
                if ev is not None and ev.far_better(view.t, window, n, c.track_chi2 / n, c.track_share):
                    drop.add(i)
        keep = [i for i in range(len(keys)) if i not in drop]
        after = round(view.d - max(split), 2) if split else None
        return resolve(fix, keep, view, self.lines, {"evidence": "track_gnss", "after_switch_m": after})
