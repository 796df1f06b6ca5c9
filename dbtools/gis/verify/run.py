"""GIS grid verification: :func:`verify_fixes` runs the steps of :mod:`dbtools.gis.verify`
(the method is described there) on a network and its fixes."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.index import grid_index
from dbtools.gis.matching import track_index_for
from dbtools.gis.verify.cells import (
    Cells,
    cell_statistics,
    classify,
    match_fixes,
    pooled_spread,
    run_cell_means,
)
from dbtools.gis.verify.cells import cell_frame as _cell_frame
from dbtools.gis.verify.cells import coverage as _coverage
from dbtools.gis.verify.cells import empty_cells as _empty_cells
from dbtools.gis.verify.cells import residual_summary as _residual_summary
from dbtools.gis.verify.config import (
    DEFECT_COLUMNS,
    FIX_COLUMNS,
    VerifyConfig,
)
from dbtools.gis.verify.defects import (
    attach_scan,
    defect_spans,
    km_defect_table,
    mark_scan_defects,
    merge_defects,
    run_backgrounds,
)
from dbtools.gis.verify.defects import defect_table as _defect_table
from dbtools.gis.verify.proposal import build_proposal as _proposal
from dbtools.gis.verify.result import GisVerification
from dbtools.gis.verify.scan import ScanResult, scan, scan_summary
from dbtools.network import Network
from schemas.errors import InputError
from schemas.tables import GIS_SPACING_M


def verify_fixes(network: Network, fixes: pd.DataFrame, cfg: VerifyConfig | None = None) -> GisVerification:
    """Map-match, test every cell and every scan window, merge defects and propose
    corrections (the steps of :mod:`dbtools.gis.verify`)."""
    cfg = cfg or VerifyConfig()
    missing = [c for c in FIX_COLUMNS if c not in fixes.columns]
    if missing:
        raise ValueError(f"fixes lack columns {missing}")
    if not len(network.gis):
        raise InputError("the DB has no GIS grid to verify", path=network.origin or None)
    gi = grid_index(network)
    index = track_index_for(network)
    grid = network.cached(("gis_verify_cells", id(gi)), lambda: Cells.build(gi, network))
    matched, counts = match_fixes(fixes, index, grid, cfg.max_offset_m)
    matched = matched.sort_values("cell", kind="stable", ignore_index=True)
    rc = run_cell_means(matched)
    # per track: runs on it and the pooled between-run spread of its cells
    track_runs = pd.Series(rc["run"].to_numpy()).groupby(grid.tid[rc["cell"].to_numpy()]).nunique()
    cells, pooled = _tested_cells(rc, matched, grid, track_runs, cfg)
    lateral, along = _scans(rc, matched, grid, cfg)
    cells = mark_scan_defects(cells, lateral.selected, grid)
    labels = merge_defects(cells, grid.tid, cfg.merge_gap_cells, grid.has_next)
    first, last = defect_spans(labels)
    backgrounds = run_backgrounds(rc, first, last, grid, round(cfg.background_m / GIS_SPACING_M))
    defects, first, last = _defect_table(labels, cells, rc, grid, pooled, track_runs, backgrounds)
    proposal = _proposal(defects, first, last, matched, grid, index.projector, cfg, backgrounds)
    defects = _finish_defects(defects, first, last, proposal, lateral.selected, grid)
    cell_frame = _cell_frame(cells, grid)
    coverage = _coverage(cells, grid, defects, rc)
    return GisVerification(
        cfg,
        cell_frame,
        defects,
        coverage,
        proposal,
        counts,
        _residual_summary(matched),
        km_defect_table(along.selected, grid),
        {"lateral": scan_summary(lateral, GIS_SPACING_M), "along_track": scan_summary(along, GIS_SPACING_M)},
    )


def _tested_cells(
    rc: pd.DataFrame, matched: pd.DataFrame, grid: Cells, track_runs: pd.Series, cfg: VerifyConfig
) -> tuple[pd.DataFrame, pd.Series]:
    """Cell statistics with their test and status (steps 2–4), and the pooled between-run
    spread per track id."""
    if not len(rc):
        return _empty_cells(), pd.Series(dtype=float)
    cells = cell_statistics(rc, matched)
    tid_c = grid.tid[cells.index.to_numpy(dtype=np.int64)]
    runs_c = cells["runs"].to_numpy(dtype=float)
    pooled_c = pooled_spread(cells["offset_spread_m"].to_numpy(dtype=float), runs_c, tid_c)
    pooled = pd.Series(pooled_c, index=tid_c).groupby(level=0).first()
    runs_on_track = np.asarray(track_runs.reindex(tid_c).to_numpy(), dtype=np.float64)
    return classify(cells, pooled_c, runs_on_track, cfg), pooled


def _scans(rc: pd.DataFrame, matched: pd.DataFrame, grid: Cells, cfg: VerifyConfig) -> tuple[ScanResult, ScanResult]:
    """The lateral scan on the runs' cell means and the along-track scan on the run-epochs'
    cell means of the km residual (step 8; nothing tested when ``cfg.scan`` is off)."""
    widths = sorted({max(1, round(w / GIS_SPACING_M)) for w in cfg.scan_windows_m}) if cfg.scan else []
    flank = max(1, round(cfg.background_m / GIS_SPACING_M))
    lateral_values = pd.DataFrame({"cell": rc["cell"], "unit": rc["run"], "v": rc["off"], "t": rc["t"]})
    km = matched[np.isfinite(matched["km_residual_m"].to_numpy())]
    n_epochs = int(km["epoch"].max()) + 1 if len(km) else 1
    km = km.assign(unit=km["run"].to_numpy() * n_epochs + km["epoch"].to_numpy())
    km_values = km.groupby(["cell", "unit"], sort=True).agg(v=("km_residual_m", "mean"), t=("t", "mean")).reset_index()
    out = []
    for values, min_shift, both in ((lateral_values, cfg.min_shift_m, False), (km_values, cfg.min_km_shift_m, True)):
        out.append(
            scan(
                values,
                grid,
                widths,
                flank,
                min_units=cfg.min_runs,
                alpha=cfg.alpha,
                correction=cfg.scan_correction,
                min_shift_m=min_shift,
                both_sides=both,
            )
        )
    return out[0], out[1]


def _finish_defects(
    defects: pd.DataFrame,
    first: npt.NDArray[np.int64],
    last: npt.NDArray[np.int64],
    proposal: pd.DataFrame,
    selected: pd.DataFrame,
    grid: Cells,
) -> pd.DataFrame:
    """The defect table's proposal and scan columns, in ``DEFECT_COLUMNS`` order."""
    if not len(defects):
        return pd.DataFrame(columns=list(DEFECT_COLUMNS))
    moved = proposal.groupby("defect_id")["shift_m"]
    defects["points_moved"] = moved.size().reindex(defects["defect_id"], fill_value=0).to_numpy()
    defects["max_move_m"] = moved.apply(lambda s: float(s.abs().max())).reindex(defects["defect_id"]).to_numpy()
    attach_scan(defects, first, last, selected, grid)
    return defects[list(DEFECT_COLUMNS)]
