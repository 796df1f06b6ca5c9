"""GIS verification, step 5 (:mod:`dbtools.gis.verify`): defect cells merged into defects,
each run's background offset beside a defect, the defect table (shift, t-test), and the
scan's windows (step 8) as defect cells, defect columns and along-track defects."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.verify.cells import Cells, effective_spread, t_test
from dbtools.gis.verify.config import DEFECT, DEFECT_COLUMNS, EDGE_CELLS, KM_DEFECT_COLUMNS

IntArray = npt.NDArray[np.int64]
#: Column of the cells frame with the sign a scan window gave its cells (merging only).
SIGN_COLUMN = "shift_sign"


def merge_defects(
    cells: pd.DataFrame, grid_tid: IntArray, max_gap_cells: int, has_next: npt.NDArray[np.bool_] | None = None
) -> pd.Series:
    """Defect number (0, 1, …) per defect cell (index = grid point id, same order); cells of
    one track with the same sign (of ``shift_sign`` where given: the scan's window, else of the
    cell's mean) and ≤ ``max_gap_cells`` cells between them share one —
    never across a kilometrage break or hole (``has_next`` false: no cell there)."""
    d = cells[cells["status"] == DEFECT]
    if d.empty:
        return pd.Series([], dtype=np.int64)
    j = d.index.to_numpy(dtype=np.int64)
    sign = np.sign(d[SIGN_COLUMN if SIGN_COLUMN in d.columns else "offset_mean_m"].to_numpy(dtype=float))
    tid = grid_tid[j]
    new = np.ones(j.size, dtype=bool)
    new[1:] = (tid[1:] != tid[:-1]) | (sign[1:] != sign[:-1]) | (np.diff(j) - 1 > max_gap_cells)
    if has_next is not None:
        holes = np.concatenate([[0], np.cumsum(~has_next)])
        new[1:] |= holes[j[1:]] - holes[j[:-1]] > 0
    return pd.Series(np.cumsum(new) - 1, index=d.index)


def defect_spans(labels: pd.Series) -> tuple[IntArray, IntArray]:
    """First and last cell (grid point ids) of each defect of :func:`merge_defects`."""
    if labels.empty:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cell_ids = pd.Series(labels.index.to_numpy(dtype=np.int64))
    lab = labels.to_numpy()
    g = cell_ids.groupby(lab)
    return np.asarray(g.min(), dtype=np.int64), np.asarray(g.max(), dtype=np.int64)


def run_backgrounds(
    rc: pd.DataFrame, first: IntArray, last: IntArray, grid: Cells, window_cells: int, skip_cells: int = EDGE_CELLS
) -> list[pd.Series]:
    """Per defect, each run's median offset (run → m) over its cells within
    ``window_cells`` either side of the defect — skipping the ``skip_cells`` next to it
    (partly displaced, or displaced but short of evidence) and every defect's cells (and
    theirs). Empty when there is no such evidence.

    The D-GPS error is correlated over minutes: a run's error beside the defect is nearly
    its error inside, so the difference removes it from the shift estimate; the median
    keeps a displaced cell that slipped into the window from biasing it."""
    out: list[pd.Series] = []
    if window_cells <= 0 or not len(first):
        return [pd.Series(dtype=float) for _ in first]
    blocked = np.zeros(grid.km.size + 1, dtype=np.int64)
    np.add.at(blocked, np.maximum(first - skip_cells, 0), 1)
    np.add.at(blocked, np.minimum(last + 1 + skip_cells, grid.km.size), -1)
    in_defect = np.cumsum(blocked)[:-1] > 0
    ref_ok = grid.has_next & ~in_defect
    cells = rc["cell"].to_numpy()  # sorted (run_cell_means)
    for a, b in zip(first, last, strict=True):
        lo, hi = max(a - skip_cells - window_cells, 0), min(b + skip_cells + window_cells, grid.km.size - 1)
        i, j = np.searchsorted(cells, [lo, hi + 1])
        c = cells[i:j]
        sel = rc.iloc[i:j][ref_ok[c] & (grid.tid[c] == grid.tid[a])]
        out.append(sel.groupby("run")["off"].median() if len(sel) else pd.Series(dtype=float))
    return out


def defect_table(
    labels: pd.Series,
    cells: pd.DataFrame,
    rc: pd.DataFrame,
    grid: Cells,
    pooled: pd.Series,
    track_runs: pd.Series,
    backgrounds: list[pd.Series],
) -> tuple[pd.DataFrame, IntArray, IntArray]:
    """Defect rows (without the proposal columns) and each defect's first/last cell.
    ``pooled`` / ``track_runs``: per track id, the pooled between-run sd and the runs;
    ``backgrounds``: per defect, :func:`run_backgrounds`."""
    if labels.empty:
        return pd.DataFrame(columns=list(DEFECT_COLUMNS)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    lab = labels.to_numpy()
    cell_ids = labels.index.to_numpy(dtype=np.int64)
    first, last = defect_spans(labels)
    n_def = first.size
    # every cell from first to last (gap cells included) belongs to the defect
    span_cells = np.concatenate([np.arange(a, b + 1) for a, b in zip(first, last, strict=True)])
    span_lab = np.repeat(np.arange(n_def), last - first + 1)
    owner = pd.Series(span_lab, index=span_cells)
    sub = rc[rc["cell"].isin(owner.index)]
    sub = sub.assign(defect=owner.reindex(sub["cell"]).to_numpy())
    per_run = sub.groupby(["defect", "run"], sort=True)["off"].mean()
    run_means = per_run.groupby(level="defect")
    raw = np.asarray(run_means.mean().reindex(range(n_def)), dtype=np.float64)
    raw_spread = np.asarray(run_means.std(ddof=1).reindex(range(n_def)), dtype=np.float64)
    runs = run_means.size().reindex(range(n_def), fill_value=0).to_numpy()
    tid = grid.tid[first]
    sd, df = effective_spread(
        raw_spread,
        runs.astype(float),
        pooled.reindex(tid).to_numpy(dtype=float),
        track_runs.reindex(tid).to_numpy(dtype=float),
    )
    _, p = t_test(raw, sd, runs.astype(float), df)
    # the shift itself: each run's mean over the defect minus its own background nearby
    shift, spread, back = raw.copy(), raw_spread.copy(), np.zeros(n_def)
    for i, b in enumerate(backgrounds):
        if b.empty:
            continue
        diff = (per_run.loc[i] - b).dropna()
        if diff.empty:
            continue
        shift[i] = float(diff.mean())
        spread[i] = float(diff.std(ddof=1)) if diff.size > 1 else np.nan
        back[i] = float(raw[i] - shift[i])
    res = sub[sub["n_res"] > 0].groupby(["defect", "run"])["res"].mean().groupby(level="defect").mean()
    fixes = sub.groupby("defect")["n"].sum().reindex(range(n_def), fill_value=0).to_numpy()
    q_min = cells.loc[cell_ids, "q_value"].groupby(lab).min().reindex(range(n_def)).to_numpy()
    g = grid.frame
    table = pd.DataFrame(
        {
            "defect_id": np.arange(1, n_def + 1),
            "track_id": g["track_id"].to_numpy()[first],
            "line_code": g["line_code"].to_numpy()[first],
            "track": g["track"].to_numpy()[first],
            "km_from_m": grid.km[first],
            "km_to_m": grid.km[last + 1],
            "length_m": grid.km[last + 1] - grid.km[first],
            "cells": last - first + 1,
            "runs": runs,
            "fixes": fixes,
            "shift_m": shift,
            "spread_m": spread,
            "background_m": back,
            "p_value": p,
            "q_min": q_min,
            "km_residual_mean_m": res.reindex(range(n_def)).to_numpy(dtype=float),
        }
    )
    return table, first, last


# ------------------------------------------------------------------------------ the scan's windows


def mark_scan_defects(cells: pd.DataFrame, selected: pd.DataFrame, grid: Cells) -> pd.DataFrame:
    """Cells (with fixes) of the scan's selected windows become defect cells, reason naming
    the window; ``shift_sign`` carries the window's sign for :func:`merge_defects` (a cell's
    own mean, with few runs, still holds their GPS errors)."""
    out = cells.assign(**{SIGN_COLUMN: np.sign(cells["offset_mean_m"].to_numpy(dtype=float))})
    for first, last, mean in zip(selected["first"], selected["last"], selected["mean_m"], strict=True):
        inside = out.index[(out.index >= first) & (out.index <= last)]
        length = float(grid.km[int(last) + 1] - grid.km[int(first)])
        out.loc[inside, "status"] = DEFECT
        out.loc[inside, "reason"] = f"offset over a {length:g} m window"
        out.loc[inside, SIGN_COLUMN] = float(np.sign(mean))
    return out


def attach_scan(defects: pd.DataFrame, first: IntArray, last: IntArray, selected: pd.DataFrame, grid: Cells) -> None:
    """Per defect, the scan window overlapping it with the largest |t| (``window_m``,
    ``scan_t``, ``scan_q``; NaN when only the cell test found it). In place."""
    cols = {"window_m": np.full(len(defects), np.nan), "scan_t": np.full(len(defects), np.nan)}
    cols["scan_q"] = np.full(len(defects), np.nan)
    if len(selected):
        s_first = selected["first"].to_numpy(dtype=np.int64)
        s_last = selected["last"].to_numpy(dtype=np.int64)
        for i, (a, b) in enumerate(zip(first, last, strict=True)):
            ov = np.flatnonzero((s_first <= b) & (s_last >= a) & (grid.tid[s_first] == grid.tid[a]))
            if not ov.size:
                continue
            j = ov[np.argmax(selected["t_stat"].abs().to_numpy()[ov])]
            cols["window_m"][i] = grid.km[s_last[j] + 1] - grid.km[s_first[j]]
            cols["scan_t"][i] = selected["t_stat"].to_numpy()[j]
            cols["scan_q"][i] = selected["q_value"].to_numpy()[j]
    for name, val in cols.items():
        defects[name] = val


def km_defect_table(selected: pd.DataFrame, grid: Cells) -> pd.DataFrame:
    """The along-track scan's selected windows as rows of ``KM_DEFECT_COLUMNS``: the mean
    residual GIS km − pipeline km over the window relative to its flanks (+: the GIS puts
    the fixes further along the km than the pipeline does)."""
    if selected.empty:
        return pd.DataFrame({c: pd.Series([], dtype=float) for c in KM_DEFECT_COLUMNS})
    a = selected["first"].to_numpy(dtype=np.int64)
    b = selected["last"].to_numpy(dtype=np.int64) + 1
    g = grid.frame
    out = pd.DataFrame(
        {
            "km_defect_id": np.arange(1, len(selected) + 1),
            "track_id": g["track_id"].to_numpy()[a],
            "line_code": g["line_code"].to_numpy()[a],
            "track": g["track"].to_numpy()[a],
            "km_from_m": grid.km[a],
            "km_to_m": grid.km[b],
            "length_m": grid.km[b] - grid.km[a],
            "run_epochs": selected["units"].to_numpy(dtype=np.int64),
            "residual_m": selected["mean_m"].to_numpy(dtype=float),
            "se_m": selected["se_m"].to_numpy(dtype=float),
            "t_stat": selected["t_stat"].to_numpy(dtype=float),
            "p_value": selected["p_value"].to_numpy(dtype=float),
            "q_value": selected["q_value"].to_numpy(dtype=float),
        }
    )
    return out[list(KM_DEFECT_COLUMNS)]
