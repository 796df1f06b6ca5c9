"""GIS grid verification from traversed trajectories [S001 §9(a), SPEC §6].

Input: GPS fixes whose track is *known* (from balises or the GPS up/down decision, never
guessed — :mod:`fieldlogs.gisverify.evidence` selects them), one row per fix with the columns of
:data:`FIX_COLUMNS`. Everything below is vectorised over fixes (no Python loop per fix or
per cell; one small loop per *defect*).

**1. Map-matching.** Each fix is matched exactly to the nearest segment of its known
track (:meth:`~dbtools.gis.matching.TrackIndex.match_xy`, within ``max_offset_m``): km
``k_i`` and signed lateral offset ``o_i`` (positive left of increasing km). Its *cell* is
the grid segment [km_j, km_j+1) that holds k_i (20 m). The along-track residual
``r_i = k_i − km_ref_i`` compares the GPS km with the pipeline's balise/feature-corrected
km where that is known well enough (``km_ref_m``; NaN otherwise).

**2. The run is the unit.** D-GPS error is Gauss–Markov with a correlation time of
minutes: over one cell (about one second at line speed), and over a few hundred metres,
it is a single draw per run. Fixes of one run in one cell are therefore not independent
evidence; they are averaged first. For cell c with runs r = 1..k_c::

    ō_rc = mean of run r's offsets in c
    m_c  = mean_r ō_rc,   s_c = sd_r ō_rc (ddof 1, the between-run spread),   se_c = s_c / √k_c

**3. Test.** H0: the cell's GIS centreline is right (μ_c = 0). The between-run spread
is a property of the receivers, not of the cell, so it is also pooled over the track
(``s_pool² = Σ(k_c − 1)s_c² / Σ(k_c − 1)``); the test uses ``s = max(s_c, s_pool)`` —
a cell's own spread only where it is larger (local multipath) — because with a handful
of runs ``s_c`` alone is often small by chance, and a small spread times a moderate mean
would then pass for a defect. ``t_c = m_c / (s/√k_c)`` against Student's t with k_c − 1
degrees of freedom for the own spread, (runs on the track − 1) for the pooled one (a
conservative count: neighbouring cells share the same runs' errors); ``p_c`` two-sided.
Over all *testable* cells the p-values are corrected for multiple testing —
Benjamini–Hochberg (false-discovery rate, default; valid under the positive dependence of
neighbouring cells) or Bonferroni (family-wise) — giving ``q_c``. A cell is a **defect
cell** when ``q_c ≤ alpha`` *and* ``|m_c| ≥ min_shift_m`` (significance alone is not
enough: with hundreds of runs a few centimetres become significant but are not worth a
DB change; the simulator's spline-vs-chord difference on 300 m curves is ~0.1 m).

**4. Status.** A cell is *unverified* — never "good" — when it has fewer than
``min_runs`` runs or ``min_fixes`` fixes ("evidence"), or when it is not a defect but its
95 % confidence interval ``|m_c| + t₀.₉₇₅·se_c`` reaches beyond ``tolerance_m``
("inconclusive": too noisy to say the centreline is right to within the tolerance — the
cells either side of a displaced stretch, which see half of it, usually land here).
Otherwise it is *verified*. Cells of the grid without any fix are unverified too; they
appear in the coverage only.

**5. Defects.** Defect cells of one track with the same sign of shift are merged when at
most ``merge_gap_cells`` cells lie between them (never across a kilometrage break). Per
defect the runs are again the unit: the per-run mean over the defect's (run, cell) means
gives a t-test p-value as in 3. The **shift** is estimated differently: each run's mean
inside the defect minus its *own* mean offset over ``background_m`` either side (the cell
next to the defect and other defects skipped). The D-GPS error of a run barely changes
over the seconds between the two (σ·√(2(1 − e^(−Δt/τ))) ≈ 0.3 m for 15 s at τ = 180 s
against 0.75 m), so the difference removes most of it: the shift's error drops from
σ/√runs to about 0.3 m/√runs (``background_m`` column: what was removed).

**6. Proposed correction.** The lateral error of the grid is taken as piecewise linear
between grid points (that is how the DB interpolates the track): a fix at fraction u of
segment j sees ``(1 − u)·e_j + u·e_{j+1}``. Per defect the point shifts e_j of the
defect's points are the weighted least-squares solution over the background-corrected
offsets (as in 5) of the fixes of its cells and of the one cell on each side (points
outside fixed at 0; each (run, cell) has total weight 1, as in 2), with a tiny ridge and
a total-variation penalty ``smooth``·Σ|Δe| (iteratively reweighted least squares on the
tridiagonal system), which flattens noise while keeping the ends of a displaced stretch
sharp; the levels of the resulting segments are then refitted without the penalty (no
shrinkage). Three Huber re-weightings (residuals beyond 2 robust sd) keep a multipath
burst that passed the trust filter from bending the fit. Points whose estimate reaches ``min_move_m`` are moved that far
perpendicular to the track (tangent from the grid points two either side, in the plane
zone of :class:`Projector`), to the left for a positive shift — where the fixes say the
track really is.

**7. Along-track residual.** Per cell the run-level mean and spread of ``r_i`` are
reported (per cell not tested: the pipeline km carries its own error, up to its margin,
correlated within a run — only cycles with a small margin provide ``km_ref_m``; the scan of
8 tests it over windows).

**8. The scan** (:mod:`~dbtools.gis.verify.scan`, ``scan`` on). With one 1 Hz fix per pass
per cell a handful of runs cannot test a cell; neighbouring cells are pooled into windows
of ``scan_windows_m`` (100–500 m): per run its mean offset in the window minus its own mean
offset over ``background_m`` either side (the slow GPS error removed, as in 5), weighted by
how little that error can drift in between; the runs' contrasts are t-tested with the
variance moderated per window length [Smyth 2004], Bonferroni (``scan_correction``) over
every window of every track. The windows it selects make their cells defect cells (merged
with those of 3 as in 5, so the shift, the proposal of 6 and the status follow the pooled
defect); cells it does not select keep the status of 4 — a window that tested clean never
makes an unverified cell verified. The same scan on the along-track residual of 7, with the
run-epoch as the unit, gives the ``km_defects`` (reported, not proposed).

Modules: :mod:`~dbtools.gis.verify.config` (thresholds, column sets),
:mod:`~dbtools.gis.verify.cells` (steps 1–4, 7 and the coverage),
:mod:`~dbtools.gis.verify.defects` (step 5 and the scan's defects),
:mod:`~dbtools.gis.verify.proposal` (step 6), :mod:`~dbtools.gis.verify.scan` (step 8),
:mod:`~dbtools.gis.verify.result` (the result and its JSON shape); :func:`verify_fixes`
runs them. All plane work is in the network's one projection (:mod:`dbtools.gis.index`).
Measured recall and false-defect rates are in ``bench/NOTES.md`` ("GIS verification").
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.index import grid_index
from dbtools.gis.matching import track_index_for
from dbtools.gis.verify.cells import (
    Cells,
    adjust_pvalues,
    cell_statistics,
    classify,
    match_fixes,
    pooled_spread,
    run_cell_means,
    t_test,
)
from dbtools.gis.verify.cells import cell_frame as _cell_frame
from dbtools.gis.verify.cells import coverage as _coverage
from dbtools.gis.verify.cells import empty_cells as _empty_cells
from dbtools.gis.verify.cells import residual_summary as _residual_summary
from dbtools.gis.verify.config import (
    CELL_COLUMNS,
    COVERAGE_COLUMNS,
    DEFECT,
    DEFECT_COLUMNS,
    FIX_COLUMNS,
    KM_DEFECT_COLUMNS,
    KM_EPOCH_COLUMN,
    PROPOSAL_COLUMNS,
    UNVERIFIED,
    VERIFIED,
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
from dbtools.gis.verify.proposal import lateral_shift, point_shifts, proposed_network, shift_grid_points
from dbtools.gis.verify.result import GisVerification
from dbtools.gis.verify.scan import ScanResult, scan, scan_summary
from dbtools.network import Network
from schemas.errors import InputError
from schemas.tables import GIS_SPACING_M

__all__ = [
    "CELL_COLUMNS",
    "COVERAGE_COLUMNS",
    "DEFECT",
    "DEFECT_COLUMNS",
    "FIX_COLUMNS",
    "KM_DEFECT_COLUMNS",
    "KM_EPOCH_COLUMN",
    "PROPOSAL_COLUMNS",
    "UNVERIFIED",
    "VERIFIED",
    "GisVerification",
    "VerifyConfig",
    "adjust_pvalues",
    "lateral_shift",
    "merge_defects",
    "point_shifts",
    "proposed_network",
    "shift_grid_points",
    "t_test",
    "verify_fixes",
]


def verify_fixes(network: Network, fixes: pd.DataFrame, cfg: VerifyConfig | None = None) -> GisVerification:
    """Map-match, test every cell and every scan window, merge defects and propose
    corrections (module docstring)."""
    cfg = cfg or VerifyConfig()
    missing = [c for c in FIX_COLUMNS if c not in fixes.columns]
    if missing:
        raise ValueError(f"fixes lack columns {missing}")
    if not len(network.gis):
        raise InputError("the DB has no GIS grid to verify", path=network.origin or None)
    gi = grid_index(network)
    index = track_index_for(network)
    grid = network.cached(("gis_verify_cells", id(gi)), lambda: Cells.build(gi))
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
