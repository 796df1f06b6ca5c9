"""The route the pipeline decides for a run: a whole replay with the GNSS aid off, for the
commands that need a line, track and facing before they position GNSS epochs on it
(``trainpos gnss position`` without ``--line/--track``). Above :mod:`fieldlogs.pipeline.run`:
no aid calls the whole pipeline."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from dbtools.network import Network
from fieldlogs.pipeline.estimate import signed_travel
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.runs.handle import Run


def decided_route(run: Run, network: Network, cfg: Any) -> tuple[str, str, int] | None:
    """(line, track, k) the pipeline decides for a run with the GNSS aid off: the line/track of
    most of its determined cycles (set by a balise pair or the GPS up/down decision) and the sign
    of km per metre of travel toward the F end on them; None when it decides none (a run
    without tacho, balises or GPS). ``cfg`` is a :class:`~fieldlogs.pipeline.config.PipelineConfig`."""
    res = run_pipeline(run, network, replace(cfg, gnss=replace(cfg.gnss, enabled=False)))
    line, track = res.summary.get("line_code"), res.summary.get("track")
    if not line or not track or res.cycles is None:
        return None
    pos = res.positions
    on = (pos["line_code"] == line).to_numpy(bool, na_value=False) & (pos["track"] == track).to_numpy(
        bool, na_value=False
    )
    s = signed_travel(res.cycles, res.odometry)
    dkm, ds = np.diff(pos["km_m"].to_numpy(dtype=float)), np.diff(s)
    moving = on[1:] & on[:-1] & np.isfinite(dkm) & (np.abs(ds) > 1e-3)
    k = 1 if not moving.any() or np.sum(np.sign(dkm[moving] * ds[moving])) >= 0 else -1
    return str(line), str(track), k
