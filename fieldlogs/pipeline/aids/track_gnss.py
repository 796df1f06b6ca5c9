"""Raw GNSS fits constrained to each candidate track as an aid [SPEC §8.3; S002].

The track-constrained pseudorange fit (:mod:`fieldlogs.gnss.ontrack`) holds the antenna on a
given track; on the wrong track the fit leaves large residuals: a track d metres to the side
shifts each range by d·cos E·sin(A − ψ), of which the clock and the along-track position absorb
only the common and along-track parts (4 m between D and U of the network sample: residual RMS
≈ 2.5–3 m against ≈ 1.5 m on the right track, tests/fieldlogs/pipeline/test_network_raw_gnss.py).
Each candidate is fitted on its own polyline: a line track of the GIS grid by (line, track,
facing by the sign of its km per forward metre), a track off the grid — a station track or a
crossover — on its ``track_points`` (:func:`fieldlogs.gnss.gis.points_track`, facing by the
sign of its pos per forward metre); the solver marks epochs beyond a short track's ends off
track, so they are not compared. While the estimate is ambiguous, at each GNSS epoch the
candidates are compared pairwise
with the GNSS aid's own test (:class:`fieldlogs.gnss.ontrack.TrackEvidence`): over the
epochs since the split (at most ``gnss.track_window_s``), when at least ``gnss.track_min_epochs``
epochs have a fit on both, the median excess of a's test statistic over b's is above
``gnss.track_chi2`` and b fits better on ``gnss.track_share`` of them, a is dropped (event
evidence ``track_gnss``).
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
                if ev is not None and ev.far_better(view.t, window, c.track_min_epochs, c.track_chi2, c.track_share):
                    drop.add(i)
        keep = [i for i in range(len(keys)) if i not in drop]
        after = round(view.d - max(split), 2) if split else None
        return resolve(fix, keep, view, self.lines, {"evidence": "track_gnss", "after_switch_m": after})
