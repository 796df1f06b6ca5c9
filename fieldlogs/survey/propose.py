"""``--propose``: the DB's tables as a source set with only the flagged items changed, and
each change with its evidence in a sidecar (``survey_changes.json`` / ``.csv``).

* a *moved* balise: ``km_actual_m`` ← DB km − residual (rounded to 1 cm), ``km_equipment_m``
  moved by the same amount, and ``dist_from_initial_m`` of every C balise whose own km or
  whose governing pair's I1 moved, by s·(Δkm_C − Δkm_I1) (s = +1 on D/S, −1 on U);
* a *confirmed* candidate C balise: a new row governed by the last initial pair before it in
  running direction (its ``dist_from_initial_m`` the km difference to that pair's I1);
  ``km_equipment_m`` is its actual km plus the equipment − actual offset of the nearest DB
  balise on its track (to be checked where a realignment begins: the sidecar says so).
  Unknown I1/I2 telegrams are listed for inspection, not proposed: an initial pair needs
  its station and both balises checked on site;
* a *new* curve with straights on both sides: six rows (``S001``, … not used on its track);
  a *moved* feature: its six rows replaced by the surveyed ones, same ``feature_id``; on a
  track off every line these are ``track_feature_points`` rows (``pos_m``) of that
  ``track_id`` (:mod:`fieldlogs.survey.features`, "Tracks off every line"), and so on a track
  along a line that holds its curves per track (the feature's ``db_table``): the surveyed km
  rows mapped back to its pos (:mod:`fieldlogs.survey.trackform`).

Balises and features that are missed, unverified or not seen are reported, never removed:
they need an inspection, not a DB edit. The proposal is checked with the ``db validate``
rules before it is written: a change that brings a new error (e.g. an I2 moved off its
pair's 5 m spacing) is not applied and the sidecar names the rule, so the source set
always builds and releases.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.atomic import atomic_folder
from dbtools.network import Network, canonical
from dbtools.sources import write_source_set
from dbtools.validate import validate_network
from fieldlogs.survey.balises import MOVED
from fieldlogs.survey.features import MOVED as F_MOVED
from fieldlogs.survey.features import NEW, proposed_rows
from fieldlogs.survey.frames import rows
from fieldlogs.survey.trackform import pos_rows
from schemas.enums import BaliseKind, Severity, direction_sign
from schemas.tables import BALISES, FEATURE_POINTS, PAIR_SPACING_M, TRACK_FEATURE_POINTS

CHANGE_COLUMNS = (
    "change_id",
    "table",
    "action",
    "key",
    "track_id",
    "line_code",
    "track",
    "old",
    "new",
    "evidence",
    "applied",
    "note",
)
SIDECAR = "survey_changes"
#: Note on the equipment km of an added balise.
EQUIPMENT_NOTE = "km_equipment_m from the nearest balise's offset: check near realignments"


@dataclass
class Change:
    """One proposed change and what applying it takes (``payload``)."""

    table: str
    action: str
    """move (a balise's km), add (a balise or a feature), replace (a feature's six rows)."""
    key: str
    line_code: str
    track: str
    old: str
    new: str
    evidence: str
    scope: dict[str, Any]
    """Finding keys this change is responsible for (balise_id, pair key, feature key)."""
    payload: Any = None
    """move: Δkm; balise add: the row; feature add/replace: the six rows."""
    note: str = ""
    applied: bool = True
    track_id: str = ""
    """The network track of the changed item (its finding's ``track_id``)."""


def _balise_moves(balises: pd.DataFrame) -> list[Change]:
    out = []
    for r in rows(balises[balises["status"] == MOVED]):
        delta = round(-float(r.residual_m), 2)
        out.append(
            Change(
                BALISES.name,
                "move",
                str(r.balise_id),
                str(r.line_code),
                str(r.track),
                f"{r.km_db_m:.2f}",
                f"{r.km_db_m + delta:.2f}",
                f"residual {r.residual_m:+.2f} m ± {r.ci95_m:.2f} (95 %), {r.n_estimates} passes, {r.reads} reads",
                {"balise_id": str(r.balise_id), "pair": (str(r.line_code), str(r.station_code), str(r.track))},
                delta,
                track_id=str(r.track_id),
            )
        )
    return out


def apply_balise_moves(b: pd.DataFrame, moves: dict[str, float]) -> pd.DataFrame:
    """Balise table with ``moves`` (balise id → Δkm) applied (module docstring)."""
    if not moves:
        return b
    b = b.copy()
    delta = b["balise_id"].astype(str).map(moves).fillna(0.0).to_numpy(dtype=float)
    key = b["line_code"].astype(str) + "/" + b["station_code"].astype(str) + "/" + b["track"].astype(str)
    is_i1 = (b["kind"] == BaliseKind.I1).to_numpy()
    d_i1 = pd.Series(delta[is_i1], index=key[is_i1].to_numpy()).groupby(level=0).first()
    gov = key.map(d_i1).fillna(0.0).to_numpy(dtype=float)
    sign = np.array([direction_sign(str(t)) for t in b["track"]], dtype=float)
    is_c = (b["kind"] == BaliseKind.C).to_numpy()
    dist = b["dist_from_initial_m"].to_numpy(dtype=float, na_value=np.nan)
    b["dist_from_initial_m"] = np.where(is_c, np.round(dist + sign * (delta - gov), 2), dist)
    b["km_actual_m"] = np.round(b["km_actual_m"].to_numpy(dtype=float) + delta, 2)
    b["km_equipment_m"] = np.round(b["km_equipment_m"].to_numpy(dtype=float) + delta, 2)
    return b


def _governing_pair(b: pd.DataFrame, line: str, track: str, km: float) -> pd.Series | None:
    """The I1 of the last pair before ``km`` in running direction on the line/track."""
    s = direction_sign(track)
    i1 = b[(b["kind"] == BaliseKind.I1) & (b["line_code"] == line) & (b["track"] == track)]
    behind = i1[s * (km - i1["km_actual_m"].to_numpy(dtype=float)) > PAIR_SPACING_M]
    if not len(behind):
        return None
    return behind.iloc[int(np.argmax(s * behind["km_actual_m"].to_numpy(dtype=float)))]


def _equipment_offset(b: pd.DataFrame, line: str, track: str, km: float) -> float:
    on = b[(b["line_code"] == line) & (b["track"] == track)]
    if not len(on):
        return 0.0
    j = int(np.argmin(np.abs(on["km_actual_m"].to_numpy(dtype=float) - km)))
    return float(on["km_equipment_m"].iloc[j] - on["km_actual_m"].iloc[j])


def _candidate_change(c: Any, b: pd.DataFrame, used: set[str]) -> Change:
    """A confirmed candidate as a new C balise (module docstring); other kinds are reported."""
    line, track, km = str(c.line_code), str(c.track), round(float(c.km_m), 2)
    ev = f"{c.reads} reads by {c.runs} runs at {km:.2f} ± {c.ci95_m:.2f} m; nearest DB balise {c.nearest_balise}"
    gov = _governing_pair(b, line, track, km) if c.kind == BaliseKind.C else None
    if gov is None:
        why = "no initial pair before it" if c.kind == BaliseKind.C else "an unknown initial-pair telegram: inspect"
        cid = str(c.candidate_id)
        return Change(BALISES.name, "add", cid, line, track, "", "", ev, {}, None, why, False, str(c.track_id))
    bid = f"{line}-{track}-S{c.candidate_id}"
    while bid in used:
        bid += "x"
    used.add(bid)
    row = {
        "balise_id": bid,
        "kind": "C",
        "line_code": line,
        "station_code": str(gov["station_code"]),
        "track": track,
        "signal_type": str(c.tel_signal_type),
        "km_actual_m": km,
        "km_equipment_m": round(km + _equipment_offset(b, line, track, km), 2),
        "dist_from_initial_m": round(abs(km - float(gov["km_actual_m"])), 2),
    }
    new = f"C {c.tel_signal_type} at {km:.2f}"
    scope = {"balise_id": bid}
    return Change(
        BALISES.name, "add", bid, line, track, "", new, ev, scope, row, EQUIPMENT_NOTE, track_id=str(c.track_id)
    )


def _candidate_changes(cands: pd.DataFrame, b: pd.DataFrame) -> list[Change]:
    if not len(cands):
        return []
    used = set(b["balise_id"].astype(str))
    return [_candidate_change(c, b, used) for c in rows(cands[cands["confirmed"].astype(bool)])]


def _next_id(used: set[str]) -> str:
    n = 1
    while f"S{n:03d}" in used:
        n += 1
    used.add(f"S{n:03d}")
    return f"S{n:03d}"


def _used_ids(fp: pd.DataFrame, tfp: pd.DataFrame) -> dict[tuple[str, str], set[str]]:
    """Feature ids in use per key: (line_code, track), and ("", track_id) off a line."""
    used = {(str(k[0]), str(k[1])): set(g["feature_id"].astype(str)) for k, g in fp.groupby(["line_code", "track"])}
    if len(tfp):
        used |= {("", str(k)): set(g["feature_id"].astype(str)) for k, g in tfp.groupby("track_id")}
    return used


def _feature_changes(features: pd.DataFrame, curves: dict[tuple[str, str], Any], network: Network) -> list[Change]:
    """New and moved features as six surveyed rows each (module docstring)."""
    out: list[Change] = []
    used = _used_ids(network.feature_points, network.track_feature_points)
    for f in rows(features[features["status"].isin([NEW, F_MOVED])]):
        off = not str(f.line_code)  # a track off every line: track_feature_points by its track_id
        key = ("", str(f.track_id)) if off else (str(f.line_code), str(f.track))
        per_track = str(f.db_table) == TRACK_FEATURE_POINTS.name  # off a line, or a track holding its own
        table = TRACK_FEATURE_POINTS.name if per_track else FEATURE_POINTS.name
        where = ("", "") if off else key
        curve = curves[key].curves.set_index("curve_id").loc[str(f.curve_id)].copy()
        curve["line_code"], curve["track"] = key
        ev = f"{f.passes} passes: exit {f.exit_km_m:.1f} ± {f.exit_ci95_m:.1f} m, R {f.radius_m:.0f} m, {f.attribute}"
        action = "add" if f.status == NEW else "replace"
        if not bool(curve["straights_ok"]):
            note = "no 20 m straight on both sides"
            cid = str(f.curve_id)
            out.append(Change(table, action, cid, *where, "", "", ev, {}, None, note, False, str(f.track_id)))
            continue
        id_key = ("", str(f.track_id)) if per_track else key
        fid = _next_id(used.setdefault(id_key, set())) if f.status == NEW else str(f.feature_id)
        old = "" if f.status == NEW else f"exit {f.exit_km_db_m:.1f}, R {f.radius_db_m:.0f} {f.attribute_db}"
        new = f"exit {f.exit_km_m:.1f}, R {float(f.radius_m):.0f} {f.attribute}"
        scope = {"track_id": id_key[1]} if per_track else {"line_code": key[0], "track": key[1]}
        six = proposed_rows(curve, fid)
        if per_track and not off:  # a track along a line: its km rows back to its pos (fieldlogs.survey.trackform)
            six = pos_rows(six, str(f.track_id), network)
        out.append(
            Change(
                table,
                action,
                fid,
                *where,
                old,
                new,
                ev,
                scope | {"feature_id": fid},
                six,
                str(f.reason or ""),
                True,
                str(f.track_id),
            )
        )
    return out


def _apply_features(frame: pd.DataFrame, changes: list[Change], where: tuple[str, ...]) -> pd.DataFrame:
    """``frame`` (feature_points or track_feature_points) with the changes' six rows: a
    replaced feature's old rows (same ``where`` keys and feature_id) dropped first."""
    for c in changes:
        if c.action == "replace":
            mine = frame["feature_id"] == c.key
            for k in where:
                mine &= frame[k] == c.scope[k]
            frame = frame[~mine]
    if changes:
        frame = pd.concat([frame, pd.DataFrame([r for c in changes for r in c.payload])], ignore_index=True)
    return frame


def apply_changes(network: Network, changes: list[Change]) -> Network:
    """The network with every applied change."""
    on = [c for c in changes if c.applied]
    b = apply_balise_moves(network.balises, {c.key: float(c.payload) for c in on if c.action == "move"})
    added = [c.payload for c in on if c.table == BALISES.name and c.action == "add"]
    if added:
        b = pd.concat([b, pd.DataFrame(added)], ignore_index=True)
    feats = [c for c in on if c.table == FEATURE_POINTS.name]
    fp = _apply_features(network.feature_points, feats, ("line_code", "track"))
    tables = dict(network.tables)
    tables[BALISES.name] = canonical(BALISES, b)
    tables[FEATURE_POINTS.name] = canonical(FEATURE_POINTS, fp)
    on_tracks = [c for c in on if c.table == TRACK_FEATURE_POINTS.name]
    if on_tracks:  # only then: a network without the table keeps it absent
        tfp = _apply_features(network.track_feature_points, on_tracks, ("track_id",))
        tables[TRACK_FEATURE_POINTS.name] = canonical(TRACK_FEATURE_POINTS, tfp)
    return Network(tables, origin="survey proposal", meta=dict(network.meta))


def _errors(network: Network) -> dict[str, dict[str, Any]]:
    return {
        f"{f.rule}|{json.dumps(f.keys, sort_keys=True, default=str)}": f.keys
        for f in validate_network(network)
        if f.severity == Severity.ERROR
    }


def _responsible(change: Change, keys: dict[str, Any]) -> bool:
    """Is ``change`` the row a finding names (balise id, pair key or feature key)?"""
    s = change.scope
    if not s:
        return False
    if "balise_id" in keys:
        return bool(keys["balise_id"] == s.get("balise_id"))
    if "station_code" in keys:
        return bool((keys.get("line_code"), keys["station_code"], keys.get("track")) == s.get("pair"))
    if "feature_id" in keys:
        return all(keys.get(k) == v for k, v in s.items())
    return False


@dataclass
class Proposal:
    """The corrected network and every change (:data:`CHANGE_COLUMNS`)."""

    network: Network
    changes: pd.DataFrame


def _guard(network: Network, changes: list[Change]) -> Network:
    """Drop the changes that bring new ``db validate`` errors (module docstring)."""
    before = set(_errors(network))
    proposed = apply_changes(network, changes)
    for _ in range(len(changes) + 1):
        new = {k: v for k, v in _errors(proposed).items() if k not in before}
        if not new:
            return proposed
        for rule_keys, keys in new.items():
            rule = rule_keys.split("|", 1)[0]
            blamed = [c for c in changes if c.applied and _responsible(c, keys)]
            for c in blamed or [c for c in changes if c.applied]:
                c.applied = False
                c.note = (c.note + "; " if c.note else "") + f"not applied: it would break rule {rule}"
        proposed = apply_changes(network, changes)
    return proposed


def build_proposal(report: Any) -> Proposal:
    """The corrected network and the change list of a :class:`~fieldlogs.survey.result.SurveyReport`."""
    network: Network = report.network
    changes = (
        _balise_moves(report.balises)
        + _candidate_changes(report.candidates, network.balises)
        + _feature_changes(report.features, report.curves, network)
    )
    proposed = _guard(network, changes) if changes else network
    table = [
        {c: getattr(ch, c) for c in CHANGE_COLUMNS if c != "change_id"} | {"change_id": i + 1}
        for i, ch in enumerate(changes)
    ]
    return Proposal(proposed, pd.DataFrame(table, columns=list(CHANGE_COLUMNS)))


def write_proposal(proposal: Proposal, folder: Path, *, force: bool = False, inputs: Iterable[Path | str] = ()) -> Path:
    """The source set and its sidecar, written atomically into ``folder``."""
    from fieldlogs.survey.result import records

    with atomic_folder(Path(folder), force=force, inputs=inputs) as tmp:
        write_source_set(proposal.network, tmp, force=True)
        text = json.dumps({"changes": records(proposal.changes)}, ensure_ascii=False, indent=2)
        (tmp / f"{SIDECAR}.json").write_text(text + "\n", encoding="utf-8")
        proposal.changes.to_csv(tmp / f"{SIDECAR}.csv", index=False, lineterminator="\n")
    return Path(folder)
