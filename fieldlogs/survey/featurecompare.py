"""Surveyed curves against the DB's feature points: ok / moved / new / not seen / unverified
(the rules are in :mod:`fieldlogs.survey.features`, "Comparison"); on tracks off every line
against ``track_feature_points``, per ``track_id``, pos in the place of km; on tracks along a
line against their ``track_feature_points`` too, mapped onto the line's km
(:mod:`fieldlogs.survey.trackform`). Each row's ``db_table`` names the table its DB feature
comes from, or for a new curve the one a proposal writes it to (the track's own
``track_feature_points`` where the track holds its curves per track or lies off every line).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pandas as pd

from dbtools.network import Network
from dbtools.topology import grid_track_ids
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.curvature import Coverage, TrackKey
from fieldlogs.survey.features import MOVED, NEW, NOT_SEEN, OK, UNVERIFIED, TrackCurves, db_features, db_track_features
from fieldlogs.survey.trackform import along_line, km_features

FEATURE_COLUMNS = (
    "track_id",
    "line_code",
    "track",
    "feature_id",
    "curve_id",
    "status",
    "reason",
    "passes",
    "attribute_db",
    "attribute",
    "radius_db_m",
    "radius_m",
    "radius_diff_share",
    "entry_km_db_m",
    "entry_km_m",
    "entry_diff_m",
    "exit_km_db_m",
    "exit_km_m",
    "exit_diff_m",
    "exit_ci95_m",
    "db_table",
)
LINE_FORM, TRACK_FORM = "feature_points", "track_feature_points"


def _overlap(a0: float, a1: float, b0: float, b1: float) -> float:
    return min(max(a0, a1), max(b0, b1)) - max(min(a0, a1), min(b0, b1))


def _judge(db: pd.Series, c: pd.Series, cfg: SurveyConfig) -> tuple[str, str, dict[str, float]]:
    d_entry = float(c["entry_km_m"] - db["entry_km_m"])
    d_exit = float(c["exit_km_m"] - db["exit_km_m"])
    r_db = float(db["radius_m"])
    d_r = float(c["radius_m"] / r_db - 1.0) if r_db > 0 else float("nan")
    reasons = []
    if max(abs(d_entry), abs(d_exit)) > cfg.feature_km_tolerance_m:
        reasons.append(f"km (entry {d_entry:+.1f} m, exit {d_exit:+.1f} m)")
    if not abs(d_r) <= cfg.feature_radius_tolerance:
        reasons.append(f"radius ({100 * d_r:+.0f} %)")
    if str(c["attribute"]) != str(db["attribute"]):
        reasons.append(f"direction ({c['attribute']} in the runs)")
    nums = {"entry_diff_m": d_entry, "exit_diff_m": d_exit, "radius_diff_share": d_r}
    return (MOVED if reasons else OK), "; ".join(reasons), nums


def _row(db: pd.Series | None, c: pd.Series | None, status: str, reason: str, passes: int) -> dict[str, object]:
    out: dict[str, object] = dict.fromkeys(FEATURE_COLUMNS, np.nan)
    src = db if db is not None else c
    assert src is not None
    out.update(line_code=src["line_code"], track=src["track"], status=status, reason=reason, passes=passes)
    if db is not None:
        out.update(
            db_table=db["db_table"],
            feature_id=db["feature_id"],
            attribute_db=db["attribute"],
            radius_db_m=db["radius_m"],
            entry_km_db_m=db["entry_km_m"],
            exit_km_db_m=db["exit_km_m"],
        )
    if c is not None:
        out.update(
            curve_id=c["curve_id"],
            attribute=c["attribute"],
            radius_m=c["radius_m"],
            entry_km_m=c["entry_km_m"],
            exit_km_m=c["exit_km_m"],
            exit_ci95_m=c["exit_ci95_m"],
        )
    return out


def compare(
    feature_points: pd.DataFrame,
    surveyed: Mapping[TrackKey, TrackCurves],
    coverage: Mapping[TrackKey, Coverage],
    cfg: SurveyConfig,
    network: Network | None = None,
    track_feature_points: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """One row per DB feature and per new curve (:data:`FEATURE_COLUMNS`); ``track_id`` the
    network track holding its entry (:func:`dbtools.topology.grid_track_ids`; without a
    network the implied ``LINE:TRACK``). The features of ``track_feature_points`` on tracks
    off every line (key ``("", track_id)``) are compared with those tracks' curves: their
    rows have no line/track, their track_id, and pos in the km columns."""
    dbf = _db_features(feature_points, track_feature_points, network)
    rows: list[dict[str, object]] = []
    matched: set[str] = set()
    for _, db in dbf.iterrows():
        key = (str(db["line_code"]), str(db["track"]))
        tc = surveyed.get(key)
        best, best_ov = None, 0.0
        if tc is not None:
            for _, c in tc.curves.iterrows():
                ov = _overlap(db["entry_km_m"], db["exit_km_m"], c["entry_km_m"], c["exit_km_m"])
                if ov > best_ov and str(c["curve_id"]) not in matched:
                    best, best_ov = c, ov
        if best is not None:
            matched.add(str(best["curve_id"]))
            status, reason, nums = _judge(db, best, cfg)
            row = _row(db, best, status, reason, int(best["passes"]))
            row.update(nums)
        else:
            cov = coverage.get(key)
            n = len(cov.passes_covering(float(db["lo"]), float(db["hi"]))) if cov is not None else 0
            seen = n >= cfg.min_passes
            why = (
                f"no curve in the runs' curvature ({n} passes)"
                if seen
                else f"too few passes covering it ({n} of {cfg.min_passes})"
            )
            row = _row(db, None, NOT_SEEN if seen else UNVERIFIED, why, n)
        rows.append(row)
    for tc in surveyed.values():
        for _, c in tc.curves.iterrows():
            if str(c["curve_id"]) in matched:
                continue
            why = "" if c["straights_ok"] else "no 20 m straight on both sides: not a feature point"
            rows.append(_row(None, c, NEW, why, int(c["passes"])))
    out = pd.DataFrame(rows, columns=list(FEATURE_COLUMNS))
    if len(out):
        out["track_id"] = _track_ids(out, network)
        off = out["line_code"] == ""
        out.loc[off, "track"] = ""
        held = set(along_line(network)) if network is not None else set()
        new = out["db_table"].isna()  # a new curve goes where its track keeps its curves
        out.loc[new, "db_table"] = np.where(off[new] | out.loc[new, "track_id"].isin(held), TRACK_FORM, LINE_FORM)
    return out


def _db_features(fp: pd.DataFrame, tfp: pd.DataFrame | None, network: Network | None) -> pd.DataFrame:
    """The DB's features of the lines, of the tracks along a line that hold their curves per
    track (:func:`fieldlogs.survey.trackform.km_features`: on the line's km) and of the
    tracks off every line (keyed ("", track_id)), each with its ``db_table``."""
    parts = [db_features(fp).assign(db_table=LINE_FORM)]
    if network is not None and len(along := km_features(network)):
        parts.append(db_features(along).assign(db_table=TRACK_FORM))
    off = _off_line(tfp, network) if tfp is not None and len(tfp) else None
    if off is not None and len(off):
        parts.append(db_track_features(off).assign(db_table=TRACK_FORM))
    parts = [p for p in parts if len(p)]
    return pd.concat(parts, ignore_index=True) if parts else _empty()


def _empty() -> pd.DataFrame:
    """No DB feature at all: :func:`db_features`' empty frame with its ``db_table``."""
    return db_features(pd.DataFrame()).assign(db_table="")


def _track_ids(out: pd.DataFrame, network: Network | None) -> pd.Series:
    """Each row's track: the declared track holding the entry km along a line
    (:func:`dbtools.topology.grid_track_ids`), its own ``track`` key off every line."""
    entry = out["entry_km_db_m"].astype(float).fillna(out["entry_km_m"].astype(float))
    net = network if network is not None else Network({})
    off = (out["line_code"] == "").to_numpy()
    ids = out["track"].astype(object).copy()
    if (~off).any():
        ids[~off] = grid_track_ids(net, out["line_code"][~off], out["track"][~off], entry[~off])
    return ids


def _off_line(tfp: pd.DataFrame, network: Network | None) -> pd.DataFrame:
    """The rows of ``track_feature_points`` on tracks off every line (no ``line_code`` in
    ``tracks``): the survey places its curves by pos only there."""
    if network is None or not len(network.tracks):
        return tfp.iloc[0:0]
    t = network.tracks
    off = set(t.loc[t["line_code"].isna() | (t["line_code"].astype(str) == ""), "track_id"].astype(str))
    return tfp[tfp["track_id"].astype(str).isin(off)]
