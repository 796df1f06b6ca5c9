"""``db diff`` summaries of the feature-point tables: ``feature_points`` (by line, track and
km) and ``track_feature_points`` (by track and pos along it), one line per feature — added or
removed with its span and curve, or what changed in its rows (radius, a common shift of km or
pos or row by row, attribute, role, rows added and removed).

The row diff itself (matched on the primary keys) is :func:`dbtools.diff.diff_table`; these
functions only read its frames (:class:`dbtools.diff_network.RowDiff`).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from dbtools.diff_network import RowDiff, km_text, records, value_text


def _metres(x: float) -> str:
    return f"{x:.1f}" if abs(x) >= 1 else f"{x:.2f}"


def _feature_key(r: dict[str, Any]) -> tuple[str, str, str]:
    if "track_id" in r:
        return (str(r["track_id"]), "", str(r["feature_id"]))
    return (str(r["line_code"]), str(r["track"]), str(r["feature_id"]))


def features_summary(td: RowDiff) -> list[str]:
    """ "feature F12 0420 D: radius 400 → 450 m", one line per feature; a feature of
    ``track_feature_points`` is named by its track ("feature F1 on track 0420-3") and its
    rows by pos_m."""
    cols = td.table.column_names
    pos = "pos_m" if "pos_m" in cols else "km_m"
    added: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    removed: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    changed: dict[tuple[str, str, str], list[_Change]] = {}
    for r in records(td.added, cols):
        added.setdefault(_feature_key(r), []).append(r)
    for r in records(td.removed, cols):
        removed.setdefault(_feature_key(r), []).append(r)
    masks = records(td.changed_cols, td.values)
    for o, n, m in zip(records(td.old, cols), records(td.new, cols), masks, strict=True):
        changed.setdefault(_feature_key(n), []).append((o, n, m))
    out = []
    for key in sorted(set(added) | set(removed) | set(changed)):
        where, track, fid = key
        label = f"feature {fid} on track {where}" if pos == "pos_m" else f"feature {fid} {where} {track}"
        add, rem, chg = added.get(key, []), removed.get(key, []), changed.get(key, [])
        if add and not rem and not chg and len(add) >= 6:
            out.append(f"{label} added ({_feature_shape(add, pos)})")
            continue
        if rem and not add and not chg and len(rem) >= 6:
            out.append(f"{label} removed ({_feature_shape(rem, pos)})")
            continue
        out.append(f"{label}: " + "; ".join(_feature_changes(add, rem, chg, pos)))
    return out


_Change = tuple[dict[str, Any], dict[str, Any], dict[str, Any]]


def _feature_changes(
    add: list[dict[str, Any]], rem: list[dict[str, Any]], chg: list[_Change], pos: str = "km_m"
) -> list[str]:
    """What changed in one feature's rows: radius, km or pos (one shift or row by row),
    attribute, role, rows added and removed."""
    parts: list[str] = []
    radius = [(o["radius_m"], n["radius_m"]) for o, n, m in chg if m["radius_m"]]
    if radius:
        parts.append(", ".join(f"radius {value_text(a)} → {value_text(b)} m" for a, b in dict.fromkeys(radius)))
    moved = [(o["seq"], o[pos], n[pos]) for o, n, m in chg if m[pos]]
    word, fmt = ("pos", _metres) if pos == "pos_m" else ("km", km_text)
    if moved:
        deltas = {round(b - a, 3) for _, a, b in moved if a is not None and b is not None}
        seqs = _seq_list(s for s, _, _ in moved)
        if len(deltas) == 1 and len(moved) > 1:
            parts.append(f"{word} {next(iter(deltas)):+.1f} m ({seqs})")
        else:
            parts.append(", ".join(f"row {s} {word} {fmt(a)} → {fmt(b)}" for s, a, b in moved))
    for c in ("attribute", "role"):
        vals = [(o["seq"], o[c], n[c]) for o, n, m in chg if m[c]]
        parts.extend(f"row {s} {c} {value_text(a)} → {value_text(b)}" for s, a, b in vals)
    if add:
        parts.append(f"{_seq_list(r['seq'] for r in add)} added")
    if rem:
        parts.append(f"{_seq_list(r['seq'] for r in rem)} removed")
    return parts


def _seq_list(seqs: Iterable[Any]) -> str:
    s = sorted(int(x) for x in seqs if x is not None)
    return ("row " if len(s) == 1 else "rows ") + ",".join(str(x) for x in s)


def _feature_shape(rows: list[dict[str, Any]], pos: str = "km_m") -> str:
    at = [r[pos] for r in rows if r[pos] is not None]
    curves = [f"{r['attribute']} R {value_text(r['radius_m'])} m" for r in rows if r["radius_m"]]
    if pos == "pos_m":
        span = f"pos {min(at):.1f}–{max(at):.1f} m" if at else "pos —"
    else:
        span = f"km {km_text(min(at))}–{km_text(max(at))}" if at else "km —"
    return span + (", " + ", ".join(curves) if curves else "")
