"""A run's route as a path of tracks (``audit_track_path``): what the audit keeps of the
track the onboard unit claimed cycle by cycle.

From the positions output (columns ``t``, ``state``, ``track_id``, ``line_code``,
``track``, ``pos_m``, ``speed_mps``, ``candidates``) the positioned cycles are kept —
state ``determined`` (one track) or ``ambiguous`` (several candidate tracks, SPEC §8:
the unit has not yet told which way a facing switch sent it). Each maximal run of
consecutive positioned cycles with the same key (the ``track_id`` for ``determined``,
"ambiguous" for ``ambiguous``) is one path entry; cycles in another state (undetermined,
uncertain) are skipped, so a track determined before and after a short uncertain stretch
stays one entry. Per entry:

* ``t_from``, ``t_to`` — first and last cycle time;
* ``distance_m`` — Σ |v|·Δt over its cycles (Δt to the next cycle; the last cycle of the
  run, or of a window, takes the cycle period ``CYCLE_S``): the distance travelled while
  positioned on it;
* ``pos_from_m``, ``pos_to_m`` — distance along the track from its begin at the first
  and last cycle (determined entries);
* ``candidates`` — ambiguous entries: the JSON list of every track that was a candidate
  in any of its cycles (sorted).

On a line-only DB a run is one entry per implied track (``LINE:TRACK``), so the table is
meaningful for every run; on a network it is the ordered sequence of tracks (station
tracks, crossovers, the branch of a junction) the run was claimed on.
"""

from __future__ import annotations

import json

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.audit.store import PATH_COLUMNS
from fieldlogs.pipeline.odometry.streams import CYCLE_S
from schemas.enums import PositionState

_AMBIGUOUS_KEY = "\0ambiguous"
_POSITIONED = (PositionState.DETERMINED.value, PositionState.AMBIGUOUS.value)


def empty_path() -> pd.DataFrame:
    return pd.DataFrame({c: pd.Series(dtype=object) for c in PATH_COLUMNS})


def _cycle_distance(t: npt.NDArray[np.float64], speed: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """|v|·Δt per cycle, Δt to the next cycle (the last one: the cycle period)."""
    dt = np.diff(t, append=t[-1] + CYCLE_S) if len(t) else np.zeros(0)
    out: npt.NDArray[np.float64] = np.abs(np.nan_to_num(speed)) * np.clip(dt, 0.0, None)
    return out


def _candidate_ids(values: pd.Series) -> str | None:
    """Union of the candidate track ids of an ambiguous entry's cycles, as a JSON list."""
    ids: set[str] = set()
    for v in values.dropna():
        ids.update(str(c["track_id"]) for c in json.loads(v) if c.get("track_id") is not None)
    return json.dumps(sorted(ids)) if ids else None


def track_path(positions: pd.DataFrame) -> pd.DataFrame:
    """The path entries of one run's (or window's) positions; columns :data:`PATH_COLUMNS`."""
    if positions.empty or "track_id" not in positions:
        return empty_path()
    t = positions["t"].to_numpy(dtype=float)
    dist = _cycle_distance(t, positions["speed_mps"].to_numpy(dtype=float, na_value=np.nan))
    state = positions["state"].astype(str)
    keep = state.isin(_POSITIONED).to_numpy()
    if not keep.any():
        return empty_path()
    p = positions.loc[keep].assign(_d=dist[keep])
    key = p["track_id"].astype(object).where(p["state"] == PositionState.DETERMINED.value, _AMBIGUOUS_KEY)
    seg = (key != key.shift()).cumsum().to_numpy()
    g = p.groupby(seg, sort=True)
    out = pd.DataFrame(
        {
            "state": g["state"].first().to_numpy(),
            "track_id": g["track_id"].first().to_numpy(),
            "line_code": g["line_code"].first().to_numpy(),
            "track": g["track"].first().to_numpy(),
            "t_from": g["t"].first().to_numpy(dtype=float),
            "t_to": g["t"].last().to_numpy(dtype=float),
            "distance_m": g["_d"].sum().to_numpy(dtype=float),
            "pos_from_m": g["pos_m"].first().to_numpy(dtype=float, na_value=np.nan),
            "pos_to_m": g["pos_m"].last().to_numpy(dtype=float, na_value=np.nan),
            "n_cycles": g["t"].size().to_numpy(dtype=int),
        }
    )
    amb = out["state"] == PositionState.AMBIGUOUS.value
    cands = g["candidates"].agg(_candidate_ids).tolist() if "candidates" in p else [None] * len(out)
    out["candidates"] = pd.Series(
        [c if a and isinstance(c, str) else None for c, a in zip(cands, amb, strict=True)], dtype=object
    )
    for c in ("track_id", "line_code", "track", "pos_from_m", "pos_to_m"):
        out[c] = out[c].astype(object).where(~amb, None)
    out["seq"] = np.arange(len(out))
    return out[list(PATH_COLUMNS)]


def append_path(earlier: pd.DataFrame, later: pd.DataFrame) -> pd.DataFrame:
    """The path of two consecutive windows of a long run: the first entry of ``later``
    continues the last of ``earlier`` when both are on the same track (or both ambiguous)."""
    if earlier.empty:
        return later.reset_index(drop=True)
    if later.empty:
        return earlier.reset_index(drop=True)
    last, first = earlier.iloc[-1], later.iloc[0]
    same = last["state"] == first["state"] and (
        last["state"] == PositionState.AMBIGUOUS.value or last["track_id"] == first["track_id"]
    )
    head = earlier.copy()
    if same:
        i = head.index[-1]
        head.loc[i, "t_to"] = first["t_to"]
        head.loc[i, "pos_to_m"] = first["pos_to_m"]
        head.loc[i, "distance_m"] = float(last["distance_m"]) + float(first["distance_m"])
        head.loc[i, "n_cycles"] = int(last["n_cycles"]) + int(first["n_cycles"])
        if last["state"] == PositionState.AMBIGUOUS.value:
            ids = {*json.loads(last["candidates"] or "[]"), *json.loads(first["candidates"] or "[]")}
            head.loc[i, "candidates"] = json.dumps(sorted(ids)) if ids else None
        later = later.iloc[1:]
    out = pd.concat([head, later], ignore_index=True) if len(later) else head.reset_index(drop=True)
    out["seq"] = np.arange(len(out))
    return out


def path_ids(path: pd.DataFrame) -> list[str]:
    """The determined track ids of a path in order, consecutive repeats folded (an
    ambiguous stretch between two entries on the same track is not a change of track)."""
    ids = [str(x) for x, s in zip(path["track_id"], path["state"], strict=True) if s == PositionState.DETERMINED.value]
    return [x for i, x in enumerate(ids) if i == 0 or ids[i - 1] != x]
