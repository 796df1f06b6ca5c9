"""Pipeline output against ground truth (simulated or surveyed runs with a ``truth`` stream)."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from schemas.enums import PositionState


def compare_with_truth(positions: pd.DataFrame, truth: pd.DataFrame) -> pd.DataFrame:
    """Per cycle: truth km (interpolated), error = km − truth, and whether it is inside the margin.

    Cycles are compared only where the pipeline claims a position (not undetermined).
    A different line or track than the truth is flagged ``wrong_track`` where the position
    is *determined* (a different ``track_id`` where the truth has one: network runs); an
    *uncertain* position (fail-safe: the onboard unit tells the driver
    not to rely on it) may carry a track in doubt.

    On a network run (the truth names ``track_id`` and ``pos_m``) two kinds of cycle have no
    km to compare and are judged along the track instead:

    * a cycle on a track off any line (a crossover, a station loop: ``km_m`` NaN) on the true
      track: error = pos − pos_true, the distance along the track;
    * an *ambiguous* cycle: covered when one of its ``candidates`` lies on the true track with
      |pos − pos_true| ≤ its margin (the true position inside one candidate's interval); its
      error is that candidate's (NaN when none is on the true track).
    """
    t = positions["t"].to_numpy(dtype=float)
    tt = truth["t"].to_numpy(dtype=float)
    km_true = np.interp(t, tt, truth["km_m"].to_numpy(dtype=float, na_value=np.nan))
    idx = np.clip(np.searchsorted(tt, t, side="right") - 1, 0, len(tt) - 1)
    line_true = truth["line_code"].astype("string").fillna("").to_numpy(dtype=object)[idx]
    track_true = truth["track"].astype("string").fillna("").to_numpy(dtype=object)[idx]
    claimed = positions["state"].to_numpy(dtype=object) != PositionState.UNDETERMINED.value
    err = positions["km_m"].to_numpy(dtype=float) - km_true
    margin = positions["margin_m"].to_numpy(dtype=float)
    line = positions["line_code"].astype("string").fillna("").to_numpy(dtype=object)
    track = positions["track"].astype("string").fillna("").to_numpy(dtype=object)
    determined = positions["state"].to_numpy(dtype=object) == PositionState.DETERMINED.value
    wrong = determined & ((line != line_true) | (track != track_true))
    if "track_id" in truth and "track_id" in positions:
        # on a network the track is its id: a station track has no U/D name, a line track is
        # cut at its switches — where the truth names one, that is what must match
        id_true = truth["track_id"].astype("string").fillna("").to_numpy(dtype=object)[idx]
        claimed_id = positions["track_id"].astype("string").fillna("").to_numpy(dtype=object)
        wrong = np.where(id_true != "", determined & (claimed_id != id_true), wrong)
        if "pos_m" in truth and "pos_m" in positions:
            pos_true = truth["pos_m"].to_numpy(dtype=float, na_value=np.nan)[idx]
            off_line = np.isnan(err) & (id_true != "") & (claimed_id == id_true)
            err = np.where(off_line, positions["pos_m"].to_numpy(dtype=float, na_value=np.nan) - pos_true, err)
            ambiguous = positions["state"].to_numpy(dtype=object) == PositionState.AMBIGUOUS.value
            if "candidates" in positions and ambiguous.any():
                err, margin = _candidate_error(positions, ambiguous, id_true, pos_true, err, margin)
    return pd.DataFrame(
        {
            "t": t,
            "claimed": claimed,
            "km_true_m": km_true,
            "error_m": np.where(claimed, err, np.nan),
            "margin_m": margin,
            "within_margin": ~claimed | (np.abs(err) <= margin),
            "wrong_track": wrong,
        }
    )


def _candidate_error(
    positions: pd.DataFrame,
    ambiguous: npt.NDArray[np.bool_],
    id_true: npt.NDArray[np.object_],
    pos_true: npt.NDArray[np.float64],
    err: npt.NDArray[np.float64],
    margin: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Error and margin of each ambiguous cycle's candidate on the true track (the one whose
    interval holds the true position, else the nearest); NaN error when none is on it."""
    err, margin = err.copy(), margin.copy()
    cands = positions["candidates"].astype("string").fillna("").to_numpy(dtype=object)
    for i in np.flatnonzero(ambiguous):
        best: tuple[float, float] | None = None
        for c in json.loads(cands[i]) if cands[i] else []:
            if str(c.get("track_id")) != id_true[i] or c.get("pos_m") is None:
                continue
            e, m = float(c["pos_m"]) - float(pos_true[i]), float(c.get("margin_m", margin[i]))
            if best is None or abs(e) - m < abs(best[0]) - best[1]:
                best = (e, m)
        err[i], margin[i] = (np.nan, margin[i]) if best is None else best
    return err, margin


def truth_summary(cmp: pd.DataFrame) -> dict[str, Any]:
    """Headline numbers of :func:`compare_with_truth`."""
    c = cmp[cmp["claimed"]]
    if c.empty:
        return {"claimed_cycles": 0}
    e = c["error_m"].abs()
    return {
        "claimed_cycles": len(c),
        "first_claim_t": float(c["t"].iloc[0]),
        "max_abs_error_m": float(e.max()),
        "rms_error_m": float(np.sqrt((c["error_m"] ** 2).mean())),
        "p95_abs_error_m": float(e.quantile(0.95)),
        "within_margin_share": float(c["within_margin"].mean()),
        "wrong_track_cycles": int(c["wrong_track"].sum()),
        "mean_margin_m": float(c["margin_m"].mean()),
    }
