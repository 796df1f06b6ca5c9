"""Which positioning unit an audit replays (``trainpos audit --unit F|R|both``).

An onboard unit sits in each driving cab and works on its own [S003 §2]
(:mod:`fieldlogs.pipeline.units`). The audit replays unit F by default, exactly as it always
has; ``R`` replays the run as the R cab's unit records it (its mirror,
:func:`fieldlogs.pipeline.units.unit_run`) and stores that unit's figures; ``both`` replays
the two, stores unit F's figures (events, trace, path of tracks) and adds the comparison
of :func:`fieldlogs.pipeline.units.compare_units` to the run's record: the cycles compared,
the largest |km_F − km_R|, the cycles where that difference exceeds the sum of the margins
(|d| > m_F + m_R: one unit is wrong beyond what it claims) or both units are determined on
different tracks, and the spans of consecutive disagreeing cycles.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.units import UNITS, compare_units, unit_run
from fieldlogs.pipeline.windows import Replayed, replay_bounded
from fieldlogs.runs.handle import Run
from schemas.audit import UNIT_CHOICES

#: Positions columns the comparison needs (all a long run's windows are kept, so only these).
COMPARED = ["t", "km_m", "margin_m", "state", "track_id"]


def check_unit(unit: str) -> str:
    """``unit`` when it is one of :data:`schemas.audit.UNIT_CHOICES`; ValueError otherwise."""
    if unit not in UNIT_CHOICES:
        raise ValueError(f"unit must be one of {', '.join(UNIT_CHOICES)}, got {unit!r}")
    return unit


def comparison_fields(cmp: dict[str, Any]) -> dict[str, Any]:
    """The ``audit_runs`` unit columns of a :func:`compare_units` summary."""
    spans = [[float(a), float(b)] for a, b in cmp["disagreements"]]
    return {
        "unit_cycles_compared": int(cmp["cycles_compared"]),
        "unit_max_difference_m": cmp["max_abs_difference_m"],
        "unit_cycles_beyond_margins": int(cmp["cycles_beyond_margins"]),
        "unit_cycles_on_other_tracks": int(cmp["cycles_on_other_tracks"]),
        "unit_disagreements": len(spans),
        "unit_disagreement_spans": json.dumps(spans),
    }


def replay_unit(
    run: Run,
    network: Network,
    cfg: PipelineConfig,
    unit: str,
    consume: Callable[[Any], None],
    scratch: Path,
) -> tuple[Replayed, dict[str, Any]]:
    """The run replayed by ``unit`` (F, R or both), each result of the unit whose figures are
    stored (R for ``R``, else F) handed to ``consume``; returns that unit's replay and the
    comparison fields (:func:`comparison_fields`; empty unless ``both``). ``scratch``: a
    folder the caller owns, for unit R's mirror of the run."""
    if unit != "both":
        return replay_bounded(unit_run(run, check_unit(unit), scratch), network, cfg, consume), {}
    kept: dict[str, list[pd.DataFrame]] = {u: [] for u in UNITS}

    def keep_f(part: Any) -> None:
        consume(part)
        kept["F"].append(part.positions[COMPARED])

    result = replay_bounded(run, network, cfg, keep_f)
    replay_bounded(unit_run(run, "R", scratch), network, cfg, lambda part: kept["R"].append(part.positions[COMPARED]))
    _, cmp = compare_units(*(pd.concat(kept[u], ignore_index=True) for u in UNITS))
    return result, comparison_fields(cmp)
