"""Where the parallel-track distance not selected goes (bench/accuracy_network.py's breakdown).

Per output cycle on parallel track (:func:`fieldlogs.pipeline.track_truth.compare_tracks`) that is
not selected, the cause is read from the engine's estimate in force on that cycle (the fix with
the latest ``t_effective`` at or before the cycle, as :func:`fieldlogs.pipeline.positions.
positions_frame` picks it):

* ``undetermined``, ``uncertain``: by the cycle's state (no position; a fail-safe spell);
* ``facing switch``: the estimate holds several candidates, one of them from a split
  (``Hypothesis.split_d``) — waiting for evidence on the branch; ``facing switch, < k fixes``
  is the part of it before the k-th trusted GPS fix (k = ``track_select.gps_min_fixes``) after
  the split, where the GPS offset test may not decide whatever the evidence;
* ``run start``: several candidates, none from a split, started by the GPS initial position
  (:mod:`fieldlogs.pipeline.aids.track_gps_initial`: the tracks within 20 m of the fixes);
* ``GPS placement``: several candidates, none from a split, placed by the topology aid after a
  line-based GPS/GNSS decision (the line's track and every parallel track within 20 m);
* ``switch in margin``: one candidate whose interval reaches over an end of its track where a
  switch joins it (the cycle's candidates include a track joined there through a switch);
* ``joint``: one candidate whose interval reaches over a plain joint (no switch);
* ``other``: what none of these describes (a wrong claim, a determined cycle on a track the
  truth does not know).

A facing switch passage never resolved (:func:`fieldlogs.pipeline.track_truth.switch_resolution`)
counts as not resolved in the issue's figure whatever the reason; :func:`unresolved` says why,
apart, where no evidence was physically possible:

* ``run ended within the lead``: the run's remaining true travel after the passage is shorter
  than the turnout's lead R·α (:func:`fieldlogs.pipeline.aids.track_imu.turnouts`): the branches
  have not yet parted by their full heading (the lateral separation x²/(2R) at x < R·α is below
  R·α²/2 — 1.13 m on a 1:12 R 300 m turnout), so neither the IMU nor a GNSS offset can tell them
  at the test's α;
* ``balise-only, no group after the switch``: in the balise-only condition (balise groups and
  pairs the only track evidence) no G telegram was read between the passage and the run's end;
* ``other``: every other unresolved passage — evidence there was, the engine did not use it.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from fieldlogs.pipeline.hypotheses import TrackLines
from fieldlogs.pipeline.types import Fix
from schemas.enums import PositionState

#: Why a facing passage stayed unresolved (module docstring), in print order.
UNRESOLVED = ("run ended within the lead", "balise-only, no group after the switch", "other")

CAUSES = (
    "facing switch, < k fixes",
    "facing switch",
    "run start",
    "GPS placement",
    "switch in margin",
    "joint",
    "uncertain",
    "undetermined",
    "other",
)


def _switch_joined(lines: TrackLines, a: str, b: str) -> bool:
    """Is ``b`` joined to an end of ``a`` through a switch (either way)?"""
    topo = lines.topo
    for end in ("begin", "end"):
        for ex in topo.exits.get((a, end), []):
            if ex.track_id == b and ex.switch_id is not None:
                return True
        for ex in topo.exits.get((b, end), []):
            if ex.track_id == a and ex.switch_id is not None:
                return True
    return False


def _one(
    state: str, fix: Fix | None, cand: object, t: float, times: tuple[np.ndarray, np.ndarray], k: int, lines: TrackLines
) -> str:
    if state in (PositionState.UNDETERMINED.value, PositionState.UNCERTAIN.value):
        return state
    if state != PositionState.AMBIGUOUS.value or fix is None:
        return "other"
    if len(fix.hyps) > 1:
        split = [h for h in fix.hyps if h.split_d is not None]
        if not split:
            return "run start" if all(h.hid < 0 for h in fix.hyps) else "GPS placement"
        fix_t, split_t = times  # trusted fixes since the last split at or before t
        t_split = split_t[max(int(np.searchsorted(split_t, t, side="right")) - 1, 0)] if len(split_t) else -np.inf
        n_after = int(np.searchsorted(fix_t, t, side="right") - np.searchsorted(fix_t, t_split, side="left"))
        return "facing switch, < k fixes" if len(fix_t) and n_after < k else "facing switch"
    own = fix.hyps[0].track_id
    others = [c["track_id"] for c in json.loads(str(cand))] if isinstance(cand, str) else []
    return "switch in margin" if any(_switch_joined(lines, own, o) for o in others if o != own) else "joint"


def causes(
    tc: pd.DataFrame,
    positions: pd.DataFrame,
    fixes: list[Fix],
    times: tuple[np.ndarray, np.ndarray],
    k: int,
    lines: TrackLines,
) -> dict[str, float]:
    """Metres of parallel distance not selected per cause (module docstring); ``tc`` the
    :func:`~fieldlogs.pipeline.track_truth.compare_tracks` frame of ``positions``, ``times`` the
    trusted GPS fixes' and the ``switch_split`` events' times (each sorted)."""
    lost = np.flatnonzero(tc["parallel"].to_numpy(dtype=bool) & ~tc["selected"].to_numpy(dtype=bool))
    out: dict[str, float] = {}
    if not len(lost):
        return out
    t = positions["t"].to_numpy(dtype=float)
    t_eff = np.array([f.t_effective for f in fixes]) if fixes else np.empty(0)
    idx = np.searchsorted(t_eff, t[lost], side="right") - 1
    state = positions["state"].to_numpy(dtype=object)
    cand = positions["candidates"].to_numpy(dtype=object, na_value=None)
    ds = tc["ds_m"].to_numpy(dtype=float)
    for i, j in zip(lost.tolist(), idx.tolist(), strict=True):
        c = _one(str(state[i]), fixes[j] if j >= 0 else None, cand[i], float(t[i]), times, k, lines)
        out[c] = out.get(c, 0.0) + float(ds[i])
    return out


def unresolved(
    passages: pd.DataFrame,
    truth: pd.DataFrame,
    balise: pd.DataFrame | None,
    balise_only: bool,
    lead_m: dict[str, float],
) -> list[tuple[str, float]]:
    """(reason, remaining true travel [m]) of each passage of ``passages`` (a
    :func:`~fieldlogs.pipeline.track_truth.switch_resolution` frame) never resolved (module
    docstring); ``balise`` the run's telegrams, ``lead_m`` each switch's R·α."""
    t = truth["t"].to_numpy(dtype=float)
    v = np.abs(truth["speed_mps"].to_numpy(dtype=float))
    run = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    g = balise.loc[balise["kind"] == "G", "t"].to_numpy(dtype=float) if balise is not None else np.empty(0)
    out = []
    for tp, sw in passages.loc[~passages["resolved"].to_numpy(dtype=bool), ["t", "switch_id"]].itertuples(index=False):
        left = float(run[-1] - np.interp(tp, t, run))
        if left < lead_m.get(str(sw), 0.0):
            out.append((UNRESOLVED[0], left))
        elif balise_only and not (g >= tp).any():
            out.append((UNRESOLVED[1], left))
        else:
            out.append((UNRESOLVED[2], left))
    return out
