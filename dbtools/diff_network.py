"""``db diff`` summaries of the network tables (SPEC §8.1): tracks, connections, switches
and track_points added, removed or changed, one plain-language line each.

* a track: its line/track, km range, length and kind; a change lists the columns that
  changed (``length 600 → 590 m``);
* a connection: ``A1 end ↔ A2 begin (both, switch W1)``; a change its navigability or switch;
* a switch: type, line and km; a *moved* switch says by how much — the km difference
  (signed, metres) and the ellipsoidal (GRS80) distance between its old and new lat/lon —
  beside its other changed columns (ports, switch number, radius…);
* track_points: per track, how many points were added, removed and moved, and the largest
  displacement of a moved point.

The row diff itself (matched on the primary keys) is :func:`dbtools.diff.diff_table`; these
functions only read its frames (:class:`RowDiff`).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
import pandas as pd

from dbtools.gis.geometry import GEOD
from dbtools.rules.common import texts
from schemas.model import Table
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES, TRACK_POINTS
from schemas.units import format_km


class RowDiff(Protocol):
    """What a summary reads of a table's row diff (``dbtools.diff.TableDiff``)."""

    table: Table
    added: pd.DataFrame
    removed: pd.DataFrame
    old: pd.DataFrame
    new: pd.DataFrame
    changed_cols: pd.DataFrame

    @property
    def values(self) -> list[str]: ...


def records(frame: pd.DataFrame, cols: list[str]) -> list[dict[str, Any]]:
    """Rows as dicts of plain Python values (None for nulls), column by column."""
    if not cols:
        return [{} for _ in range(len(frame))]
    lists = [frame[c].astype(object).where(frame[c].notna(), None).tolist() for c in cols]
    return [dict(zip(cols, vals, strict=True)) for vals in zip(*lists, strict=True)]


def value_text(v: Any) -> str:
    """A cell for a summary line: — for null, %g for floats."""
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return "—"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def km_text(v: Any) -> str:
    """A km for a summary line (— for null)."""
    return "—" if v is None else format_km(float(v), 1)


def _changes(td: RowDiff) -> list[tuple[dict[str, Any], dict[str, Any], list[str]]]:
    """(old row, new row, changed columns) of every changed row."""
    cols = td.table.column_names
    masks = records(td.changed_cols, td.values)
    return [
        (o, n, [c for c in td.values if m[c]])
        for o, n, m in zip(records(td.old, cols), records(td.new, cols), masks, strict=True)
    ]


def _plain(o: dict[str, Any], n: dict[str, Any], cols: list[str], unit: dict[str, str] | None = None) -> list[str]:
    unit = unit or {}
    return [f"{c} {value_text(o[c])} → {value_text(n[c])}{unit.get(c, '')}" for c in cols]


def _track_label(r: dict[str, Any]) -> str:
    where = (
        f"{r['line_code']} {value_text(r['track'])}, km {km_text(r['km_begin_m'])}–{km_text(r['km_end_m'])}, "
        if r["line_code"]
        else ""
    )
    return f"track {r['track_id']} ({where}{value_text(r['length_m'])} m, {r['kind']})"


def tracks_summary(td: RowDiff) -> list[str]:
    cols = NETWORK_TRACKS.column_names
    out = [f"{_track_label(r)} added" for r in records(td.added, cols)]
    out += [f"{_track_label(r)} removed" for r in records(td.removed, cols)]
    for o, n, changed in _changes(td):
        out.append(f"track {n['track_id']}: " + "; ".join(_plain(o, n, changed, {"length_m": " m"})))
    return out


def _conn_label(r: dict[str, Any]) -> str:
    at = f", switch {r['switch_id']}" if r["switch_id"] else ""
    return f"connection {r['track_a']} {r['end_a']} ↔ {r['track_b']} {r['end_b']} ({r['navigability']}{at})"


def connections_summary(td: RowDiff) -> list[str]:
    cols = CONNECTIONS.column_names
    out = [f"{_conn_label(r)} added" for r in records(td.added, cols)]
    out += [f"{_conn_label(r)} removed" for r in records(td.removed, cols)]
    for o, n, changed in _changes(td):
        out.append(
            f"connection {n['track_a']} {n['end_a']} ↔ {n['track_b']} {n['end_b']}: " + "; ".join(_plain(o, n, changed))
        )
    return out


def _switch_label(r: dict[str, Any]) -> str:
    at = f" at {r['line_code']} km {km_text(r['km_m'])}" if r["line_code"] and r["km_m"] is not None else ""
    n = f" 1:{value_text(r['switch_number'])}" if r["switch_number"] is not None else ""
    return f"switch {r['switch_id']} ({r['type']}{n}{at})"


def _moved(o: dict[str, Any], n: dict[str, Any]) -> str | None:
    """``moved +10.0 m in km (400 → 410), 10.0 m by lat/lon`` when km or lat/lon changed."""
    parts = []
    if o["km_m"] is not None and n["km_m"] is not None and o["km_m"] != n["km_m"]:
        parts.append(f"{n['km_m'] - o['km_m']:+.1f} m in km ({km_text(o['km_m'])} → {km_text(n['km_m'])})")
    coords = (o["lat"], o["lon"], n["lat"], n["lon"])
    if None not in coords and (o["lat"], o["lon"]) != (n["lat"], n["lon"]):
        _, _, d = GEOD.inv(o["lon"], o["lat"], n["lon"], n["lat"])
        parts.append(f"{float(d):.1f} m by lat/lon")
    return "moved " + ", ".join(parts) if parts else None


def switches_summary(td: RowDiff) -> list[str]:
    cols = SWITCHES.column_names
    out = [f"{_switch_label(r)} added" for r in records(td.added, cols)]
    out += [f"{_switch_label(r)} removed" for r in records(td.removed, cols)]
    for o, n, changed in _changes(td):
        moved = _moved(o, n)
        rest = _plain(o, n, [c for c in changed if c not in ("km_m", "lat", "lon")], {"diverging_radius_m": " m"})
        if moved is None:
            rest = _plain(o, n, changed)
        out.append(f"switch {n['switch_id']}: " + "; ".join(([moved] if moved else []) + rest))
    return out


def track_points_summary(td: RowDiff) -> list[str]:
    """One line per track with changed points."""
    count: dict[str, dict[str, int]] = defaultdict(lambda: {"added": 0, "removed": 0, "moved": 0})
    worst: dict[str, float] = defaultdict(float)
    for kind, frame in (("added", td.added), ("removed", td.removed)):
        for t in texts(frame["track_id"]):
            count[str(t)][kind] += 1
    if len(td.old):
        o, n = td.old, td.new
        _, _, d = GEOD.inv(
            o["lon"].to_numpy(float), o["lat"].to_numpy(float), n["lon"].to_numpy(float), n["lat"].to_numpy(float)
        )
        for t, dist in zip(texts(n["track_id"]), np.atleast_1d(d), strict=True):
            count[str(t)]["moved"] += 1
            worst[str(t)] = max(worst[str(t)], float(dist))
    out = []
    for t in sorted(count):
        c = count[t]
        parts = [f"{c[k]} {k}" for k in ("added", "removed") if c[k]]
        if c["moved"]:
            parts.append(f"{c['moved']} changed (moved up to {worst[t]:.2f} m)")
        out.append(f"track_points of {t}: " + ", ".join(parts))
    return out


#: Table name → its summary.
NETWORK_SUMMARIES: dict[str, Callable[[RowDiff], list[str]]] = {
    NETWORK_TRACKS.name: tracks_summary,
    CONNECTIONS.name: connections_summary,
    SWITCHES.name: switches_summary,
    TRACK_POINTS.name: track_points_summary,
}
