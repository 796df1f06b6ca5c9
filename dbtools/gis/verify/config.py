"""GIS verification: the thresholds (:class:`VerifyConfig`) and the column sets of the
input fixes and of the result frames (method: :mod:`dbtools.gis.verify`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Literal

#: Columns of the fixes given to :func:`verify_fixes` (``km_ref_m`` may be NaN).
FIX_COLUMNS = ("run_id", "t", "lat", "lon", "line_code", "track", "km_ref_m")
#: Cell status values.
VERIFIED, UNVERIFIED, DEFECT = "verified", "unverified", "defect"
#: Columns of :attr:`GisVerification.cells` (one row per cell with at least one fix).
CELL_COLUMNS = (
    "line_code",
    "track",
    "km_from_m",
    "km_to_m",
    "runs",
    "fixes",
    "offset_mean_m",
    "offset_spread_m",
    "offset_fix_sd_m",
    "se_m",
    "t_stat",
    "p_value",
    "q_value",
    "km_residual_mean_m",
    "km_residual_spread_m",
    "km_residual_runs",
    "status",
    "reason",
)
#: Columns of :attr:`GisVerification.defects`.
DEFECT_COLUMNS = (
    "defect_id",
    "line_code",
    "track",
    "km_from_m",
    "km_to_m",
    "length_m",
    "cells",
    "runs",
    "fixes",
    "shift_m",
    "spread_m",
    "background_m",
    "p_value",
    "q_min",
    "km_residual_mean_m",
    "points_moved",
    "max_move_m",
)
#: Columns of :attr:`GisVerification.coverage` (one row per line/track of the DB).
COVERAGE_COLUMNS = (
    "line_code",
    "track",
    "cells",
    "length_km",
    "verified_km",
    "unverified_km",
    "defect_km",
    "verified_share",
    "unverified_share",
    "defect_share",
    "defects",
    "runs",
    "fixes",
)
#: Columns of :attr:`GisVerification.proposal` (one row per GIS point moved).
PROPOSAL_COLUMNS = ("defect_id", "line_code", "track", "km_m", "shift_m", "lat", "lon", "lat_new", "lon_new")
#: Cells next to a defect that may still be displaced (half-displaced, or short of evidence):
#: left out of the background, and their points part of the proposal's fit.
EDGE_CELLS = 2
#: Iterations and |Δe| floor [m] of the total-variation smoothing of proposed shifts.
TV_ITERATIONS, TV_EPS_M = 50, 1e-3
#: Huber re-weighting of the proposal's fixes: iterations and threshold (× robust sd).
HUBER_ITERATIONS, HUBER_K = 3, 2.0
#: Neighbouring point shifts closer than this after the total variation are one segment [m].
TV_SEGMENT_TOL_M = 0.02
#: Longest grid segment counted as a cell in the coverage [m] (longer = a hole or a break).
MAX_CELL_M = 200.0


@dataclass(frozen=True)
class VerifyConfig:
    """Thresholds of the verification (module docstring, steps 3–6)."""

    alpha: float = 0.01
    """Significance level after the multiple-testing correction (FDR for BH)."""
    correction: Literal["bh", "bonferroni"] = "bh"
    """Multiple-testing correction over all testable cells."""
    min_shift_m: float = 0.5
    """Smallest mean lateral offset worth correcting [m]."""
    min_runs: int = 3
    """Fewer runs through a cell → unverified (the run is the independent unit)."""
    min_fixes: int = 5
    """Fewer fixes in a cell → unverified."""
    tolerance_m: float = 1.5
    """A cell is verified only if its 95 % CI of the mean offset lies within ±this [m]."""
    max_offset_m: float = 10.0
    """Fixes farther than this from their known track are not evidence [m]."""
    merge_gap_cells: int = 1
    """Defect cells with at most this many cells between them form one defect."""
    background_m: float = 200.0
    """Each run's own offset within this distance either side of a defect is its local
    GPS error, subtracted when estimating the shift (0 = off) [m]."""
    min_move_m: float = 0.25
    """Proposed point shifts smaller than this are not applied [m]."""
    ridge: float = 1e-3
    """Ridge of the least-squares point shifts, relative to the mean data weight per point."""
    smooth: float = 1.0
    """Total-variation penalty on neighbouring point shifts [m × mean data weight per
    point]: flattens noise inside a displaced stretch but keeps its ends sharp (the levels
    are then refitted without the penalty)."""

    def __post_init__(self) -> None:
        if not 0 < self.alpha < 1:
            raise ValueError("alpha must be in (0, 1)")
        if self.correction not in ("bh", "bonferroni"):
            raise ValueError("correction must be 'bh' or 'bonferroni'")
        if self.min_runs < 2:
            raise ValueError("min_runs must be at least 2 (a spread needs two runs)")
        if min(self.tolerance_m, self.max_offset_m) <= 0 or self.min_shift_m < 0 or self.min_fixes < 1:
            raise ValueError("thresholds must be positive")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
