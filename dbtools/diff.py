"""``db diff``: what changed between two DB versions (or source sets), table by table.

Rows are matched on their domain keys, the declared primary keys (balises by
``balise_id``; gis by ``(line_code, track, km_m)``; feature_points by
``(line_code, track, feature_id, seq)``; track_feature_points by
``(track_id, feature_id, seq)``; lines by ``line_code``; km_breaks by
``(line_code, track, km_from_m)``), with one outer merge per table. A matched row is
*changed* when any other column differs: nulls equal nulls, floats are equal within
``FLOAT_ATOL`` (far below survey precision, so ``12k345.6`` and ``12345.6`` written in two
source sets do not show up as a change). Float key columns are rounded to ``KEY_DECIMALS``
before matching for the same reason.

On top of the row diff come the domain summaries a maintainer reads at a glance: moved GIS
points grouped into contiguous km runs with their geodesic displacement, moved balises
with their signed shift, feature points whose radius or km (pos) changed
(:mod:`dbtools.diff_features`), the network's tracks, connections, switches (a moved
switch with its km shift and lat/lon displacement) and track_points
(:mod:`dbtools.diff_network`), and the meta changes (schema version, db_version, content
hash).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.database import read_network, schema_version
from dbtools.diff_features import features_summary
from dbtools.diff_network import NETWORK_SUMMARIES
from dbtools.diff_network import records as _records
from dbtools.diff_network import value_text as _val
from dbtools.gis.geometry import GEOD
from dbtools.gis.index import network_georef
from dbtools.network import Network, content_hash
from dbtools.sources import read_source_set
from schemas.enums import Severity
from schemas.errors import FindingsError
from schemas.model import Table
from schemas.tables import (
    BALISES,
    DB_TABLES,
    FEATURE_POINTS,
    GIS,
    GIS_SPACING_M,
    KM_BREAKS,
    LINES,
    TRACK_FEATURE_POINTS,
)
from schemas.units import format_km

#: Two floats closer than this are equal (metres or degrees: 1e-9° ≈ 0.1 mm).
FLOAT_ATOL = 1e-9
#: Float key columns (kilometrages) are rounded to this many decimals before matching.
KEY_DECIMALS = 6
#: Summary lines per table before "… N more" (the row list always has everything).
MAX_SUMMARY_LINES = 40
#: Ids listed in one "n balises added at station …" line.
MAX_IDS = 10

CHANGE_KINDS = ("removed", "added", "changed")


@dataclass
class TableDiff:
    """Row differences of one table, matched on its primary key.

    ``old`` and ``new`` hold the changed rows (declared columns), aligned row by row;
    ``changed_cols`` is a boolean frame over the non-key columns of those rows.
    """

    table: Table
    added: pd.DataFrame
    removed: pd.DataFrame
    old: pd.DataFrame
    new: pd.DataFrame
    changed_cols: pd.DataFrame

    @property
    def key(self) -> list[str]:
        return list(self.table.primary_key)

    @property
    def values(self) -> list[str]:
        return [c for c in self.table.column_names if c not in self.table.primary_key]

    @property
    def counts(self) -> dict[str, int]:
        return {"added": len(self.added), "removed": len(self.removed), "changed": len(self.old)}

    @property
    def n_changes(self) -> int:
        return len(self.added) + len(self.removed) + len(self.old)

    def rows(self) -> list[dict[str, Any]]:
        """Every difference as ``{"change", "keys", "changes": {col: [old, new]}}``.

        Removed rows first, then added, then changed, each in key order. Added and removed
        rows list their non-null values (the other side is ``null``); changed rows list only
        the columns that changed.
        """
        out: list[dict[str, Any]] = []
        for kind, frame in (("removed", self.removed), ("added", self.added)):
            keys = _records(frame, self.key)
            vals = _records(frame, self.values)
            for k, v in zip(keys, vals, strict=True):
                pairs = {c: ([x, None] if kind == "removed" else [None, x]) for c, x in v.items() if x is not None}
                out.append({"change": kind, "keys": k, "changes": pairs})
        keys = _records(self.new, self.key)
        olds = _records(self.old, self.values)
        news = _records(self.new, self.values)
        masks = self.changed_cols[self.values].to_numpy(dtype=bool) if len(self.old) else np.zeros((0, 0), bool)
        for i, (k, o, n) in enumerate(zip(keys, olds, news, strict=True)):
            cols = [c for c, m in zip(self.values, masks[i], strict=True) if m]
            out.append({"change": "changed", "keys": k, "changes": {c: [o[c], n[c]] for c in cols}})
        return out

    def to_dict(self) -> dict[str, Any]:
        return {**self.counts, "rows": self.rows()}


@dataclass
class DbDiff:
    """Everything ``db diff`` reports: both sides, schema/meta changes, tables, summary."""

    old: dict[str, Any]
    new: dict[str, Any]
    schema_version: tuple[int | None, int | None]
    meta: dict[str, tuple[str | None, str | None]]
    tables: dict[str, TableDiff]
    summary: list[str] = field(default_factory=list)

    @property
    def has_changes(self) -> bool:
        """True when any content row differs (meta-only changes do not count)."""
        return any(t.n_changes for t in self.tables.values())

    def to_dict(self) -> dict[str, Any]:
        """The documented JSON shape (see the module docstring of ``cli/db.py``)."""
        return {
            "old": self.old,
            "new": self.new,
            "schema_version": {"old": self.schema_version[0], "new": self.schema_version[1]},
            "meta": {k: [o, n] for k, (o, n) in self.meta.items()},
            "tables": {name: t.to_dict() for name, t in self.tables.items()},
            "summary": list(self.summary),
        }


# --------------------------------------------------------------------------- loading


def load_network(path: Path, *, verify: bool = True) -> tuple[Network, int | None]:
    """A DB file or a source-set folder → (network, schema version; None for sources).

    Source sets with errors raise :class:`FindingsError`; unreadable input raises
    :class:`InputError`. ``verify``: a DB file's content hash is checked
    (:mod:`dbtools.integrity`); False for reports that state a mismatch themselves.
    """
    path = Path(path)
    if path.is_dir():
        network, findings = read_source_set(path)
        errors = [f for f in findings if f.severity == Severity.ERROR]
        if errors:
            raise FindingsError(f"{len(errors)} error(s) in the source set; cannot diff it", findings, path=path)
        return network, None
    network = read_network(path, verify=verify)
    return network, schema_version(path)


def diff_paths(old: Path, new: Path) -> DbDiff:
    """Load both sides (DB files or source sets) and diff them. A DB whose content does not
    match its stored content hash is diffed as it is, and the summary says so first."""
    old_net, old_sv = load_network(old, verify=False)
    new_net, new_sv = load_network(new, verify=False)
    return diff_networks(old_net, new_net, schema_versions=(old_sv, new_sv))


# --------------------------------------------------------------------------- the diff


def diff_networks(
    old: Network, new: Network, *, schema_versions: tuple[int | None, int | None] | None = None
) -> DbDiff:
    """Pure diff of two networks. Schema versions come from ``schema_versions`` (the DB's
    ``PRAGMA user_version``) or else from each side's ``meta['schema_version']``."""
    if schema_versions is None:
        schema_versions = (_meta_int(old.meta, "schema_version"), _meta_int(new.meta, "schema_version"))
    tables = {t.name: diff_table(t, old.tables[t.name], new.tables[t.name]) for t in DB_TABLES}
    old_hash, new_hash = content_hash(old.tables), content_hash(new.tables)
    old_side, new_side = _side(old, old_hash), _side(new, new_hash)
    keys = sorted((set(old_side) | set(new_side)) - {"origin", "kind", "actual_content_hash", "content_verified"})
    meta = {k: (old_side.get(k), new_side.get(k)) for k in keys if old_side.get(k) != new_side.get(k)}
    d = DbDiff(old_side, new_side, schema_versions, meta, tables)
    d.summary = summarize(d, old, new)
    for label, side in (("NEW", new_side), ("OLD", old_side)):
        if side["content_verified"] is False:
            d.summary.insert(
                0,
                f"{label} ({side['origin']}): content does not match its stored content_hash (edited after build, "
                f"or a bit flip): stored {str(side['content_hash'])[:12]}…, actual {side['actual_content_hash'][:12]}…",
            )
    return d


def diff_table(table: Table, old: pd.DataFrame, new: pd.DataFrame) -> TableDiff:
    """Added, removed and changed rows of one table (one outer merge on the primary key)."""
    key = list(table.primary_key)
    values = [c for c in table.column_names if c not in key]
    cols = table.column_names
    o = _keyed(table, old[cols])
    n = _keyed(table, new[cols])
    m = o.merge(n, on=key, how="outer", suffixes=("_old", "_new"), indicator=True, sort=True)
    where = m["_merge"].astype(str).to_numpy()
    removed = _side_rows(m[where == "left_only"], key, values, "_old")
    added = _side_rows(m[where == "right_only"], key, values, "_new")
    both = m[where == "both"]
    differs = pd.DataFrame({c: _differs(both[f"{c}_old"], both[f"{c}_new"]) for c in values}, index=both.index)
    any_diff = differs.any(axis=1).to_numpy(dtype=bool) if values else np.zeros(len(both), dtype=bool)
    changed = both[any_diff]
    return TableDiff(
        table,
        added=added,
        removed=removed,
        old=_side_rows(changed, key, values, "_old"),
        new=_side_rows(changed, key, values, "_new"),
        changed_cols=differs[any_diff].reset_index(drop=True),
    )


def _keyed(table: Table, frame: pd.DataFrame) -> pd.DataFrame:
    """Round float key columns so that equal kilometrages match whatever their notation.

    Text keys are merged as plain objects: pandas' Arrow-backed strings fail to merge when
    one side is empty.
    """
    frame = frame.copy()
    for k in table.primary_key:
        dtype = table.column(k).dtype
        if dtype == "float":
            frame[k] = frame[k].round(KEY_DECIMALS)
        elif dtype == "str":
            frame[k] = frame[k].astype(object).where(frame[k].notna(), None)
    return frame


def _side_rows(m: pd.DataFrame, key: list[str], values: list[str], suffix: str) -> pd.DataFrame:
    out = m[key + [f"{c}{suffix}" for c in values]]
    return out.set_axis(key + values, axis=1).reset_index(drop=True)


def _differs(a: pd.Series, b: pd.Series) -> np.ndarray:
    """Element-wise "not equal", nulls equal to nulls, floats within ``FLOAT_ATOL``."""
    na_a = a.isna().to_numpy()
    na_b = b.isna().to_numpy()
    if pd.api.types.is_float_dtype(a.dtype) and pd.api.types.is_float_dtype(b.dtype):
        x = a.to_numpy(dtype=float)
        y = b.to_numpy(dtype=float)
        with np.errstate(invalid="ignore"):
            same = np.abs(x - y) <= FLOAT_ATOL
    else:
        x = a.astype(object).where(~na_a, None).to_numpy()
        y = b.astype(object).where(~na_b, None).to_numpy()
        same = np.asarray(x == y, dtype=bool)
    return np.asarray(np.where(na_a | na_b, na_a != na_b, ~same), dtype=bool)


def _meta_int(meta: dict[str, str], key: str) -> int | None:
    try:
        return int(meta[key])
    except (KeyError, TypeError, ValueError):
        return None


def _side(net: Network, actual_hash: str) -> dict[str, Any]:
    """What the report says about one side: origin, kind and its meta.

    A source set has no stored content hash: the one a build would store is given instead.
    ``actual_content_hash`` is the hash of the content as read; ``content_verified`` says
    whether it is the stored one (None for a source set).
    """
    kind = "sources" if net.files else "db"
    side: dict[str, Any] = {"origin": net.origin, "kind": kind, **net.meta}
    side.setdefault("content_hash", actual_hash)
    side["actual_content_hash"] = actual_hash
    side["content_verified"] = None if kind == "sources" else side["content_hash"] == actual_hash
    return side


# --------------------------------------------------------------------------- summaries


def _georef_summary(old: Network, new: Network) -> list[str]:
    """Changes of operating area, metric CRS and height datum (stated in meta, or derived
    from the points for a DB built without them)."""
    a, b = network_georef(old), network_georef(new)
    if a is None or b is None:
        return []
    out = []
    if a.crs_epsg != b.crs_epsg:
        out.append(f"metric CRS EPSG:{a.crs_epsg} ({a.crs_source}) → EPSG:{b.crs_epsg} ({b.crs_source})")
    if a.area != b.area:
        out.append(f"operating area {a.area.describe()} ({a.area_source}) → {b.area.describe()} ({b.area_source})")
    if a.heights != b.heights:
        out.append(f"height datum {a.heights} → {b.heights}")
    return out


def _counts_summary(td: TableDiff) -> list[str]:
    """One line of counts for a table with no dedicated summary (the network tables)."""
    c = td.counts
    return [f"{td.table.name}: {c['added']} added, {c['removed']} removed, {c['changed']} changed"]


def summarize(d: DbDiff, old: Network, new: Network) -> list[str]:
    """Plain-language lines, meta first, then one block per table in dependency order."""
    lines: list[str] = []
    sv_old, sv_new = d.schema_version
    if sv_old != sv_new and sv_old is not None and sv_new is not None:
        lines.append(f"schema version {sv_old} → {sv_new}")
    v_old, v_new = old.meta.get("db_version"), new.meta.get("db_version")
    if v_old != v_new and v_old and v_new:
        lines.append(f"db_version {v_old} → {v_new}")
    lines.extend(_georef_summary(old, new))
    h_old, h_new = d.old["content_hash"], d.new["content_hash"]
    if h_old != h_new:
        lines.append(f"content_hash {h_old[:12]}… → {h_new[:12]}…")
    builders = {
        LINES.name: _lines_summary,
        GIS.name: _gis_summary,
        BALISES.name: _balises_summary,
        FEATURE_POINTS.name: features_summary,
        TRACK_FEATURE_POINTS.name: features_summary,
        KM_BREAKS.name: _km_breaks_summary,
        **NETWORK_SUMMARIES,
    }
    for t in DB_TABLES:
        td = d.tables[t.name]
        if td.n_changes:
            build = builders.get(t.name, _counts_summary)
            lines.extend(_capped(build(td), t.name))
    if not d.has_changes:
        n = sum(len(new.tables[t.name]) for t in DB_TABLES)
        same = d.old["actual_content_hash"] == d.new["actual_content_hash"]
        lines.append(
            f"no content differences ({n} rows compared)"
            if same
            else f"no content differences above the comparison tolerance ({n} rows compared), but the content "
            f"hashes differ: values differ below {FLOAT_ATOL:g}"
        )
    return lines


def _capped(lines: list[str], table: str) -> list[str]:
    if len(lines) <= MAX_SUMMARY_LINES:
        return lines
    more = len(lines) - MAX_SUMMARY_LINES
    return [*lines[:MAX_SUMMARY_LINES], f"… {more} more {table} lines (see the row list)"]


def _km(metres: Any) -> str:
    if metres is None or pd.isna(metres):
        return "—"
    m = float(metres)
    return format_km(m, 0) if abs(m - round(m)) < 1e-6 else format_km(m, 1)


def _km1(metres: Any) -> str:
    return "—" if metres is None or pd.isna(metres) else format_km(float(metres), 1)


def _metres(x: float) -> str:
    return f"{x:.1f}" if abs(x) >= 1 else f"{x:.2f}"


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _runs(frame: pd.DataFrame) -> pd.Series:
    """Run id per row of a (line_code, track, km_m)-sorted frame: a new run starts on a
    new line/track or where the km step is not one grid spacing."""
    same_lt = (frame["line_code"].astype(object).eq(frame["line_code"].astype(object).shift())) & (
        frame["track"].astype(object).eq(frame["track"].astype(object).shift())
    )
    step = frame["km_m"].diff().to_numpy(dtype=float, na_value=np.nan)
    contiguous = same_lt.to_numpy(dtype=bool) & (np.abs(step - GIS_SPACING_M) < 1e-6)
    return pd.Series(np.cumsum(~contiguous), index=frame.index)


def _gis_runs(frame: pd.DataFrame, what: str, dist: np.ndarray | None = None) -> list[str]:
    """ "GIS 0420 D km 12k000–12k300: 16 points moved, mean 2.4 m, max 3.1 m"."""
    if frame.empty:
        return []
    f = frame[["line_code", "track", "km_m"]].copy()
    f["_d"] = dist if dist is not None else np.nan
    f = f.sort_values(["line_code", "track", "km_m"], kind="stable").reset_index(drop=True)
    f["_run"] = _runs(f)
    g = f.groupby("_run", sort=True)
    agg = pd.DataFrame(
        {
            "line_code": g["line_code"].first(),
            "track": g["track"].first(),
            "km_from": g["km_m"].min(),
            "km_to": g["km_m"].max(),
            "n": g.size(),
            "mean": g["_d"].mean(),
            "max": g["_d"].max(),
        }
    )
    out = []
    for line, track, lo, hi, n, mean, mx in agg.itertuples(index=False, name=None):
        where = f"GIS {line} {track} km {_km(lo)}" + (f"–{_km(hi)}" if n > 1 else "")
        text = f"{where}: {_plural(int(n), 'point')} {what}"
        if dist is not None:
            text += f", mean {_metres(mean)} m, max {_metres(mx)} m" if n > 1 else f" {_metres(mx)} m"
        out.append(text)
    return out


def _gis_summary(td: TableDiff) -> list[str]:
    out: list[str] = []
    if len(td.old):
        mask = td.changed_cols
        moved = (mask["lat"] | mask["lon"]).to_numpy(dtype=bool)
        if moved.any():
            o, n = td.old[moved], td.new[moved]
            _, _, dist = GEOD.inv(
                o["lon"].to_numpy(dtype=float),
                o["lat"].to_numpy(dtype=float),
                n["lon"].to_numpy(dtype=float),
                n["lat"].to_numpy(dtype=float),
            )
            out.extend(_gis_runs(n, "moved", np.asarray(dist, dtype=float)))
        height = mask["height_m"].to_numpy(dtype=bool) & ~moved
        if height.any():
            out.extend(_gis_runs(td.new[height], "changed height only"))
    out.extend(_gis_runs(td.added, "added"))
    out.extend(_gis_runs(td.removed, "removed"))
    return out


def _balise_label(r: dict[str, Any]) -> str:
    return f"balise {r['balise_id']} ({r['kind']}, {r['line_code']} {r['station_code']} {r['track']})"


def _balises_summary(td: TableDiff) -> list[str]:
    out: list[str] = []
    olds = _records(td.old, td.table.column_names)
    news = _records(td.new, td.table.column_names)
    masks = _records(td.changed_cols, td.values)
    for o, n, m in zip(olds, news, masks, strict=True):
        parts: list[str] = []
        head = _balise_label(n)
        if m["km_actual_m"]:
            if o["km_actual_m"] is not None and n["km_actual_m"] is not None:
                head += f" moved {n['km_actual_m'] - o['km_actual_m']:+.1f} m"
            head += f" (km_actual {_km1(o['km_actual_m'])} → {_km1(n['km_actual_m'])})"
        if m["km_equipment_m"]:
            parts.append(f"km_equipment {_km1(o['km_equipment_m'])} → {_km1(n['km_equipment_m'])}")
        if m["dist_from_initial_m"]:
            parts.append(f"dist_from_initial {_val(o['dist_from_initial_m'])} → {_val(n['dist_from_initial_m'])} m")
        for c in ("kind", "line_code", "station_code", "track", "signal_type"):
            if m[c]:
                parts.append(f"{c} {_val(o[c])} → {_val(n[c])}")
        sep = "; " if m["km_actual_m"] else ": "
        out.append(head + (sep + "; ".join(parts) if parts else ""))
    for kind, frame in (("added", td.added), ("removed", td.removed)):
        out.extend(_balise_groups(frame, kind))
    return out


def _balise_groups(frame: pd.DataFrame, kind: str) -> list[str]:
    """ "3 balises added at station 05 (0420 D): B124, B125, B126"."""
    if frame.empty:
        return []
    out = []
    recs = _records(frame, BALISES.column_names)
    groups: dict[tuple[object, ...], list[dict[str, Any]]] = {}
    for r in recs:  # an S003 pair's station, or a European group's identity (kind G)
        group: tuple[object, ...] = ("G", r["nid_c"], r["nid_bg"]) if r["kind"] == "G" else ()
        groups.setdefault(group or (r["line_code"], r["station_code"], r["track"]), []).append(r)
    for key, rs in sorted(groups.items(), key=lambda kv: tuple(str(x) for x in kv[0])):
        if len(rs) == 1:
            r = rs[0]
            out.append(f"{_balise_label(r)} {kind} at km_actual {_km1(r['km_actual_m'])}")
            continue
        ids = [str(r["balise_id"]) for r in rs]
        listed = ", ".join(ids[:MAX_IDS]) + (f", … ({len(ids) - MAX_IDS} more)" if len(ids) > MAX_IDS else "")
        where = (
            f"in balise group {_val(key[1])}:{_val(key[2])} (track {_val(rs[0]['track_id'])})"
            if key[0] == "G"
            else f"at station {key[1]} ({key[0]} {key[2]})"
        )
        out.append(f"{len(rs)} balises {kind} {where}: {listed}")
    return out


def _lines_summary(td: TableDiff) -> list[str]:
    out = [f"line {r['line_code']} added ({_val(r['name'])})" for r in _records(td.added, LINES.column_names)]
    out += [f"line {r['line_code']} removed ({_val(r['name'])})" for r in _records(td.removed, LINES.column_names)]
    for o, n, m in zip(
        _records(td.old, LINES.column_names),
        _records(td.new, LINES.column_names),
        _records(td.changed_cols, td.values),
        strict=True,
    ):
        parts = [f"{c} {_val(o[c])} → {_val(n[c])}" for c in td.values if m[c]]
        out.append(f"line {n['line_code']}: " + "; ".join(parts))
    return out


def _km_breaks_summary(td: TableDiff) -> list[str]:
    cols = KM_BREAKS.column_names

    def label(r: dict[str, Any]) -> str:
        return f"km break {r['line_code']} {r['track']} at {_km1(r['km_from_m'])}"

    out = [f"{label(r)} added (→ {_km1(r['km_to_m'])})" for r in _records(td.added, cols)]
    out += [f"{label(r)} removed (→ {_km1(r['km_to_m'])})" for r in _records(td.removed, cols)]
    for o, n in zip(_records(td.old, cols), _records(td.new, cols), strict=True):
        out.append(f"{label(n)}: km_to {_km1(o['km_to_m'])} → {_km1(n['km_to_m'])}")
    return out
