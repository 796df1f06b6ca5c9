"""GIS verification: the thresholds (:class:`VerifyConfig`) and the column sets of the
input fixes and of the result frames (method: :mod:`dbtools.gis.verify`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from schemas.settings import SettingError, check_ranges, setting

#: Columns of the fixes given to :func:`verify_fixes` (``km_ref_m`` may be NaN).
FIX_COLUMNS = ("run_id", "t", "lat", "lon", "line_code", "track", "km_ref_m")
#: Optional fix column: the pipeline's count of absolute fixes (balise, feature) at the fix.
#: Its km error is reset by each, so along-track residuals are compared within one epoch.
KM_EPOCH_COLUMN = "km_ref_epoch"
#: Cell status values.
VERIFIED, UNVERIFIED, DEFECT = "verified", "unverified", "defect"
#: Columns of :attr:`GisVerification.cells` (one row per cell with at least one fix).
CELL_COLUMNS = (
    "track_id",
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
    "track_id",
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
    "window_m",
    "scan_t",
    "scan_q",
)
#: Columns of :attr:`GisVerification.km_defects` (the along-track scan's windows).
KM_DEFECT_COLUMNS = (
    "km_defect_id",
    "track_id",
    "line_code",
    "track",
    "km_from_m",
    "km_to_m",
    "length_m",
    "run_epochs",
    "residual_m",
    "se_m",
    "t_stat",
    "p_value",
    "q_value",
)
#: Columns of :attr:`GisVerification.coverage` (one row per track of the grid, keyed by ``track_id``).
COVERAGE_COLUMNS = (
    "track_id",
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
PROPOSAL_COLUMNS = (
    "defect_id",
    "track_id",
    "line_code",
    "track",
    "km_m",
    "shift_m",
    "lat",
    "lon",
    "lat_new",
    "lon_new",
)
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


#: Multiple-testing corrections: Benjamini–Hochberg (false-discovery rate) or Bonferroni (family-wise).
CORRECTIONS = ("bh", "bonferroni")


@dataclass(frozen=True)
class VerifyConfig:
    """GIS verification from traversed trajectories [S001 §9(a)], section [gis_verify] (dbtools.gis.verify).

    Steps 3–8 of :mod:`dbtools.gis.verify` use these; the scan (step 8) pools the cells of
    windows of ``scan_windows_m`` along each track. Measurements behind the defaults are in
    ``bench/NOTES.md`` ("GIS verification").
    """

    alpha: float = setting(0.01, "significance level after the multiple-testing correction", gt=0, le=0.5)
    correction: str = setting("bh", "multiple-testing correction over the cells: bh or bonferroni")
    min_shift_m: float = setting(0.5, "smallest mean lateral offset worth correcting", "m", ge=0)
    min_runs: int = setting(3, "fewer runs through a cell or window → unverified (the run is the unit)", ge=2)
    min_fixes: int = setting(5, "fewer fixes in a cell → unverified", ge=1)
    tolerance_m: float = setting(
        1.5, "a cell is verified only if its 95 % CI of the mean offset is within ±this", "m", gt=0
    )
    max_offset_m: float = setting(10.0, "fixes farther than this from their known track are not evidence", "m", gt=0)
    merge_gap_cells: int = setting(1, "defect cells with at most this many cells between them form one defect", ge=0)
    background_m: float = setting(
        200.0, "each run's own offset this far either side of a window or defect is its local GPS error", "m", ge=0
    )
    min_move_m: float = setting(0.25, "proposed point shifts smaller than this are not applied", "m", ge=0)
    ridge: float = setting(1e-3, "ridge of the least-squares point shifts (× mean data weight per point)", ge=0)
    smooth: float = setting(
        1.0, "total-variation penalty on neighbouring point shifts (× mean data weight per point)", ge=0
    )
    scan: bool = setting(True, "pool neighbouring cells: test windows of scan_windows_m along each track")
    scan_windows_m: tuple[float, ...] = setting(
        (100.0, 140.0, 200.0, 300.0, 400.0, 500.0),
        "window lengths of the scan (rounded to whole 20 m cells)",
        "m",
        gt=0,
    )
    scan_correction: str = setting(
        "bonferroni", "multiple-testing correction over every window of every track: bonferroni or bh"
    )
    min_km_shift_m: float = setting(
        1.0, "smallest mean along-track (km) residual over a window worth reporting", "m", ge=0
    )
    max_km_margin_m: float = setting(
        10.0, "pipeline margin up to which its km is the along-track reference of a fix", "m", ge=0
    )

    def __post_init__(self) -> None:
        check_ranges(self, "gis_verify")
        for key in ("correction", "scan_correction"):
            value = getattr(self, key)
            if value not in CORRECTIONS:
                raise SettingError(f"'gis_verify.{key}' = {value!r} is not one of {', '.join(CORRECTIONS)}")
        if not self.scan_windows_m and self.scan:
            raise SettingError("'gis_verify.scan_windows_m' is empty while 'gis_verify.scan' is true")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
