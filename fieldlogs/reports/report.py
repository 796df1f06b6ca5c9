"""Audit reports: per route, run or vehicle aggregates from an audit database (SPEC §7).

Position-correction percentages (SPEC §5.2: |correction| / distance travelled since the
previous correction × 100) are aggregated over **balise corrections only**, as the papers
report them per balise (mean 0.29 % Tohoku line, 0.37 % Kawagoe line, target 0.5 %). A
feature-point correction often follows a balise within a few hundred metres, which makes
its percentage meaningless; feature-point corrections are counted separately
(``n_feature_corrections``, ``n_feature_refused`` with the failed diagnostics).

A track is named by one key, ``track_id``, everywhere; ``line_code`` and ``track`` are its
display names (empty for a track off any line: a crossover, a connecting curve). Columns of
every grouping (route = the run's track_id — the track it was claimed on most,
:mod:`fieldlogs.audit.runner` — and direction; run; vehicle; track = track_id), after the
keys and display names:

==========================  ==========================================================
n_runs                      runs audited without error
distance_m                  travelled distance (corrected odometry) [m]
n_corrections               balise corrections
mean/median/max_correction_pct  over the balise corrections that have a % (the first
                            one after power-up has no previous correction)
share_above_target          share of those above the target %
n_feature_corrections       accepted feature-point corrections
n_feature_refused           refused ones; ``refusal_reasons``: "diagnostic count, ..."
n_slips                     slip + slide episodes; ``n_slips_readhered`` re-adhered within
                            the maximum correction time; ``max_slip_error_m`` largest
                            error budget ½·Δa·t² (eq. 13)
gps_decisions               up/down (track) decisions from trusted GPS fixes;
                            ``n_gps_disagrees`` decisions contradicting the balise track;
                            ``gps_trusted_share`` mean share of trusted fixes
n_failsafe, n_anomalies     fail-safe events (slip correction too long), balise anomalies
==========================  ==========================================================

Per track (``--by track``) the rows come from the runs' paths of tracks
(``audit_track_path``, :mod:`fieldlogs.audit.track_path`): ``n_runs`` = runs claimed on the
track, ``distance_m`` = distance travelled while determined on it, and the events counted
on a track are those whose time falls within a determined stretch on it (an event during an
ambiguous or undetermined stretch belongs to no track); ``n_failsafe`` and ``n_anomalies``
are then counted from those events, ``gps_decisions`` from its ``track_decision`` events and
``gps_trusted_share`` (a figure of the whole run) is left empty.

Runs audited with ``--unit both`` (:mod:`fieldlogs.audit.units`) are listed in ``units``
with the two units' comparison: cycles compared, largest |km_F − km_R|, cycles beyond the
sum of the margins or on other tracks, and the disagreement spans.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.audit.store import read_meta, read_table
from fieldlogs.pipeline.corrections import STAT_COLUMNS, correction_stats
from schemas.audit import AUDIT_EVENTS, AUDIT_RUNS, AUDIT_TRACK_PATH
from schemas.enums import CORRECTION_EVENTS, SLIP_EVENTS, EventType
from schemas.jsonable import jsonable

By = Literal["route", "run", "vehicle", "track"]
#: What a route is grouped by, and its columns with the display names.
ROUTE_KEYS = ["track_id", "direction"]
ROUTE_COLUMNS = ["track_id", "line_code", "track", "direction"]
#: What a track is grouped by, and its columns with the display names.
TRACK_KEYS = ["track_id"]
TRACK_COLUMNS = ["track_id", "line_code", "track"]
#: Display names of a track (empty off a line; the unknown route's are UNKNOWN).
NAMES = ["line_code", "track"]
#: Per-route (or per-group) statistics, in the order reports show them: position correction …
CORRECTION_STATS = ["n_runs", "distance_m", *STAT_COLUMNS]
#: … and everything else.
OTHER_STATS = [
    "n_feature_corrections",
    "n_feature_refused",
    "refusal_reasons",
    "n_slips",
    "n_slips_readhered",
    "max_slip_error_m",
    "gps_decisions",
    "n_gps_disagrees",
    "gps_trusted_share",
    "n_failsafe",
    "n_anomalies",
]
UNKNOWN = "—"
"""Route key of runs whose position was never determined."""

ROUTE_JSON_KEYS = (
    "track_id",
    "line_code",
    "track",
    "direction",
    "n_runs",
    "n_corrections",
    "distance_m",
    "mean_correction_pct",
    "median_correction_pct",
    "max_correction_pct",
    "share_above_target",
)
TRACK_JSON_KEYS = ("track_id", "line_code", "track", *ROUTE_JSON_KEYS[4:])
RUN_JSON_KEYS = (
    "run_id",
    "vehicle_id",
    "unit",
    "track_id",
    "line_code",
    "track",
    "n_corrections",
    "mean_correction_pct",
    "n_slips",
    "n_failsafe",
)
VEHICLE_JSON_KEYS = (
    "vehicle_id",
    "n_runs",
    "n_corrections",
    "distance_m",
    "mean_correction_pct",
    "median_correction_pct",
    "max_correction_pct",
    "share_above_target",
)
#: Columns of the units' comparison (``--unit both``), per run.
UNIT_COLUMNS = [
    "unit_cycles_compared",
    "unit_max_difference_m",
    "unit_cycles_beyond_margins",
    "unit_cycles_on_other_tracks",
    "unit_disagreements",
    "unit_disagreement_spans",
]
UNIT_JSON_KEYS = ("run_id", "vehicle_id", *UNIT_COLUMNS[:-1])
RUN_VIEW = [
    "run_path",
    "run_id",
    "vehicle_id",
    "unit",
    *ROUTE_COLUMNS,
    "distance_m",
    "n_corrections",
    "mean_correction_pct",
    "max_correction_pct",
    "n_feature_corrections",
    "n_feature_refused",
    "n_slips",
    "n_failsafe",
    "n_anomalies",
    "max_margin_m",
]
COUNT_COLUMNS = (
    "n_corrections",
    "n_feature_corrections",
    "n_feature_refused",
    "n_slips",
    "n_slips_readhered",
    "n_gps_disagrees",
)


@dataclass
class Report:
    by: str
    target_pct: float
    groups: pd.DataFrame
    """One row per route / run / vehicle (``by``)."""
    routes: pd.DataFrame
    """One row per route (``ROUTE_COLUMNS``: track_id, its display names, direction)."""
    runs: pd.DataFrame
    """One row per run audited without error (columns ``RUN_VIEW``)."""
    vehicles: pd.DataFrame
    corrections: pd.DataFrame
    """Every balise and feature-point correction (``type``) with its route, amount, % and
    distance since the previous correction (``distance_since_m``)."""
    meta: dict[str, str]
    failed_runs: pd.DataFrame
    """run_path, error of the runs recorded with status error."""
    tracks: pd.DataFrame
    """One row per track claimed by some run (``TRACK_COLUMNS`` + the statistics)."""
    paths: pd.DataFrame
    """Every run's path of tracks (``audit_track_path`` rows of the runs audited without
    error, with their run_id), in run_path, seq order."""
    units: pd.DataFrame
    """run_id, vehicle_id and ``UNIT_COLUMNS`` of the runs audited with both units."""


def _details(frame: pd.DataFrame) -> list[dict[str, Any]]:
    return [json.loads(d) if isinstance(d, str) and d else {} for d in frame["detail"]]


def build_report(audit_path: Path, *, by: By = "route", target_pct: float = 0.5) -> Report:
    """Aggregate an audit database (read-only)."""
    runs_all = read_table(audit_path, AUDIT_RUNS.name, order_by=("run_path",))
    # runs in run_path order whatever order the workers finished them in (each run's events
    # in their own order): the same audit gives the same report and the same plots
    events = read_table(audit_path, AUDIT_EVENTS.name).sort_values("run_path", kind="stable", ignore_index=True)
    meta = read_meta(audit_path)
    runs = _named(runs_all[runs_all["status"] == "ok"].copy())
    failed = runs_all.loc[runs_all["status"] == "error", ["run_path", "error"]].reset_index(drop=True)
    for c in ["direction", "vehicle_id", "run_id", "unit"]:
        runs[c] = runs[c].fillna(UNKNOWN).astype(str)
    ev = events.merge(runs[["run_path", "run_id", "vehicle_id", *ROUTE_COLUMNS]], on="run_path", how="inner")
    ev["correction_pct"] = pd.to_numeric(ev["correction_pct"])
    corr = ev[ev["type"].isin(CORRECTION_EVENTS)].copy()
    corr["distance_since_m"] = pd.to_numeric(
        pd.Series([d.get("distance_since_correction_m", np.nan) for d in _details(corr)], index=corr.index, dtype=float)
    )
    slips = ev[ev["type"].isin(SLIP_EVENTS)].copy()
    sd = _details(slips)
    slips["readhered"] = pd.Series([bool(d.get("readhered")) for d in sd], index=slips.index, dtype=bool)
    slips["max_error_m"] = pd.Series([float(d.get("max_error_m") or 0.0) for d in sd], index=slips.index, dtype=float)
    refused = ev[ev["type"] == EventType.FEATURE_REFUSED].copy()
    refused["reasons"] = pd.Series(
        [",".join(d.get("failed", [])) or "unknown" for d in _details(refused)], index=refused.index, dtype=object
    )
    parts = {"corr": corr, "slips": slips, "refused": refused, "ev": ev}
    paths = read_table(audit_path, AUDIT_TRACK_PATH.name, order_by=("run_path", "seq"))
    paths = paths.merge(runs[["run_path", "run_id"]], on="run_path", how="inner")
    tracks = _by_track(paths, parts, target_pct)

    routes = _with_names(_aggregate(runs, parts, ROUTE_KEYS, target_pct), runs, ROUTE_COLUMNS)
    by_run = _aggregate(runs, parts, ["run_path"], target_pct)
    run_cols = runs[["run_path", "run_id", "vehicle_id", "unit", *ROUTE_COLUMNS, "max_margin_m"]]
    run_view = run_cols.merge(by_run, on="run_path", how="left")[RUN_VIEW]
    vehicles = _aggregate(runs, parts, ["vehicle_id"], target_pct)
    groups = {
        "route": routes,
        "run": run_cols.merge(by_run, on="run_path", how="left"),
        "vehicle": vehicles,
        "track": tracks,
    }[by]
    return Report(
        by,
        target_pct,
        groups.reset_index(drop=True),
        routes,
        run_view.reset_index(drop=True),
        vehicles,
        corr.reset_index(drop=True),
        meta,
        failed,
        tracks,
        paths,
        runs.loc[runs["unit"] == "both", ["run_id", "vehicle_id", *UNIT_COLUMNS]].reset_index(drop=True),
    )


def _named(frame: pd.DataFrame) -> pd.DataFrame:
    """``track_id`` and its display names filled: a missing track id is UNKNOWN (the route of
    runs never positioned, whose names are UNKNOWN too), a missing name of a known track is
    empty (a track off any line)."""
    known = frame["track_id"].notna().to_numpy()
    frame["track_id"] = frame["track_id"].fillna(UNKNOWN).astype(str)
    for c in NAMES:
        frame[c] = np.where(known, frame[c].fillna("").astype(str), UNKNOWN)
    return frame


def _with_names(groups: pd.DataFrame, named: pd.DataFrame, columns: list[str]) -> pd.DataFrame:
    """Groups keyed by track_id with its display names from ``named`` (after :func:`_named`)
    inserted after it, in ``columns`` order."""
    names = named.groupby("track_id", sort=True)[NAMES].first().reset_index()
    out = groups.merge(names, on="track_id", how="left")
    return out[[*columns, *[c for c in out.columns if c not in columns]]]


def _on_track(frame: pd.DataFrame, stretches: pd.DataFrame) -> pd.DataFrame:
    """The rows of an event frame whose ``t`` falls within a determined stretch of their run,
    with that stretch's ``TRACK_KEYS`` (instead of the run's ``ROUTE_COLUMNS``)."""
    if frame.empty or stretches.empty:
        return frame.iloc[:0].drop(columns=ROUTE_COLUMNS, errors="ignore").assign(**dict.fromkeys(TRACK_KEYS, ""))
    left = frame.drop(columns=ROUTE_COLUMNS, errors="ignore").assign(t=pd.to_numeric(frame["t"])).sort_values("t")
    right = stretches[["run_path", "t_from", "t_to", *TRACK_KEYS]].sort_values("t_from")
    m = pd.merge_asof(left, right, left_on="t", right_on="t_from", by="run_path", direction="backward")
    return m[m["t"] <= m["t_to"]].drop(columns=["t_from", "t_to"])


def _by_track(paths: pd.DataFrame, parts: dict[str, pd.DataFrame], target: float) -> pd.DataFrame:
    """Per track statistics (module docstring): the determined stretches stand for runs."""
    det = _named(paths[paths["state"] == "determined"].copy())
    det["t_from"] = pd.to_numeric(det["t_from"])
    det["t_to"] = pd.to_numeric(det["t_to"])
    on = {k: _on_track(v, det) for k, v in parts.items()}
    ev = on["ev"]
    per_run = det.groupby(["run_path", *TRACK_KEYS], sort=True).agg(distance_m=("distance_m", "sum")).reset_index()
    if per_run.empty:
        cols = [*TRACK_COLUMNS, *CORRECTION_STATS, *OTHER_STATS]
        return pd.DataFrame({c: pd.Series(dtype=object) for c in cols})

    def count(kind: str) -> npt.NDArray[np.int64]:
        sel = ev[ev["type"] == kind]
        n: pd.Series = sel.groupby(["run_path", *TRACK_KEYS]).size()
        idx = pd.MultiIndex.from_frame(per_run[["run_path", *TRACK_KEYS]])
        return n.reindex(idx, fill_value=0).to_numpy(dtype=np.int64)

    pseudo = per_run.assign(
        n_failsafe=count(EventType.FAILSAFE),
        n_anomalies=count(EventType.BALISE_ANOMALY),
        gps_decisions=count(EventType.TRACK_DECISION),
        gps_trusted_share=np.nan,
    )
    return _with_names(_aggregate(pseudo, on, TRACK_KEYS, target), det, TRACK_COLUMNS)


def _aggregate(runs: pd.DataFrame, parts: dict[str, pd.DataFrame], keys: list[str], target: float) -> pd.DataFrame:
    """One row per distinct ``keys`` of the runs; see the module docstring for the columns."""
    base = runs.groupby(keys, sort=True).agg(
        n_runs=("run_path", "size"),
        distance_m=("distance_m", "sum"),
        n_failsafe=("n_failsafe", "sum"),
        n_anomalies=("n_anomalies", "sum"),
        gps_decisions=("gps_decisions", "sum"),
        gps_trusted_share=("gps_trusted_share", "mean"),
    )
    idx = base.index

    def per(frame: pd.DataFrame, col: str, how: Any) -> pd.Series:
        if frame.empty:
            return pd.Series(np.nan, index=idx)
        out: pd.Series = frame.groupby(keys)[col].agg(how).reindex(idx)
        return out

    corr = parts["corr"]
    slips, refused, ev = parts["slips"], parts["refused"], parts["ev"]
    stats = correction_stats(corr, keys, population="balise", target_pct=target, index=idx)
    out = base.assign(
        **{c: stats[c] for c in STAT_COLUMNS},
        n_feature_corrections=per(corr[corr["type"] == EventType.FEATURE_CORRECTION], "type", "size"),
        n_feature_refused=per(refused, "type", "size"),
        refusal_reasons=per(refused, "reasons", ",".join),
        n_slips=per(slips, "type", "size"),
        n_slips_readhered=per(slips, "readhered", "sum"),
        max_slip_error_m=per(slips, "max_error_m", "max"),
        n_gps_disagrees=per(ev[ev["type"] == EventType.GPS_TRACK_DISAGREES], "type", "size"),
    )
    for c in COUNT_COLUMNS:
        out[c] = out[c].fillna(0).astype(int)
    for c in ("n_runs", "n_failsafe", "n_anomalies", "gps_decisions"):
        out[c] = out[c].fillna(0).astype(int)
    out["refusal_reasons"] = [_count_reasons(s) for s in out["refusal_reasons"]]
    return out[[*CORRECTION_STATS, *OTHER_STATS]].reset_index()


def _count_reasons(joined: Any) -> str:
    """ "a,b" + "," + "a" → "a 2, b 1" (empty when nothing was refused)."""
    if not isinstance(joined, str) or not joined:
        return ""
    counts: dict[str, int] = {}
    for r in joined.split(","):
        counts[r] = counts.get(r, 0) + 1
    return ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))


def _num(v: Any) -> Any:
    """JSON value (:func:`schemas.jsonable.jsonable`), the unknown route key as null."""
    return None if isinstance(v, str) and v == UNKNOWN else jsonable(v)


def _value(key: str, v: Any) -> Any:
    """:func:`_num`, and an empty display name (a track off any line) as null."""
    return None if key in NAMES and v == "" else _num(v)


def _records(frame: pd.DataFrame, keys: tuple[str, ...]) -> list[dict[str, Any]]:
    rows = frame[list(keys)].itertuples(index=False)
    return [{k: _value(k, v) for k, v in zip(keys, row, strict=True)} for row in rows]


def report_json(report: Report) -> dict[str, Any]:
    """The documented, stable JSON shape (whatever ``by`` is)::

        {"target_pct": 0.5,
         "routes": [{track_id, line_code, track, direction, n_runs, n_corrections, distance_m,
                     mean_correction_pct, median_correction_pct, max_correction_pct,
                     share_above_target}],
         "runs": [{run_id, vehicle_id, unit, track_id, line_code, track, n_corrections,
                   mean_correction_pct, n_slips, n_failsafe}],
         "vehicles": [{vehicle_id, n_runs, n_corrections, distance_m, mean_correction_pct,
                       median_correction_pct, max_correction_pct, share_above_target}],
         "failed_runs": [{run_path, error}],
         "tracks": [{track_id, line_code, track, n_runs, n_corrections, distance_m,
                     mean_correction_pct, median_correction_pct, max_correction_pct,
                     share_above_target}],
         "paths": [{run_id, path: [{track_id, state, candidates, t_from, t_to, distance_m}]}],
         "units": [{run_id, vehicle_id, unit_cycles_compared, unit_max_difference_m,
                    unit_cycles_beyond_margins, unit_cycles_on_other_tracks, unit_disagreements,
                    unit_disagreement_spans: [[t_from, t_to]]}]}

    Corrections and their % are balise corrections; unknown values are null, and so are the
    line_code and track of a track off any line; ``candidates`` (ambiguous stretches) is the
    list of candidate track ids; ``units`` lists the runs audited with ``--unit both``.
    """
    return {
        "target_pct": report.target_pct,
        "routes": _records(report.routes, ROUTE_JSON_KEYS),
        "runs": _records(report.runs, RUN_JSON_KEYS),
        "vehicles": _records(report.vehicles, VEHICLE_JSON_KEYS),
        "failed_runs": _records(report.failed_runs, ("run_path", "error")),
        "tracks": _records(report.tracks, TRACK_JSON_KEYS),
        "paths": [
            {"run_id": _num(g["run_id"].iloc[0]), "path": [_stretch(r) for r in g.itertuples(index=False)]}
            for _, g in report.paths.groupby("run_path", sort=True)
        ],
        "units": [
            {**rec, "unit_disagreement_spans": json.loads(str(spans or "[]"))}
            for rec, spans in zip(
                _records(report.units, UNIT_JSON_KEYS), report.units["unit_disagreement_spans"], strict=True
            )
        ],
    }


def _stretch(row: Any) -> dict[str, Any]:
    cands = json.loads(row.candidates) if isinstance(row.candidates, str) and row.candidates else None
    return {
        "track_id": _num(row.track_id),
        "state": row.state,
        "candidates": cands,
        "t_from": _num(row.t_from),
        "t_to": _num(row.t_to),
        "distance_m": _num(row.distance_m),
    }
