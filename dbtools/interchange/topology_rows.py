"""The railML topology a reader found → rows of ``tracks``, ``connections`` and ``switches``
(:mod:`schemas.network`).

* ``tracks``: one row per railML track / netElement (per piece where a railML 2 switch
  inside a track cuts it, :mod:`~dbtools.interchange.topology2`), our export's line carriers
  excepted. ``track_id`` verbatim (railML 3: our export's ``tpos:trackId``, else ``@id``);
  ``line_code`` and local ``track`` from the ``--line-code`` map / the railML line (empty
  for a track in no line); ``kind`` as stated (railML 2 ``@type``; railML 3 our
  ``tpos:kind``), else ``main`` on a line and ``connecting`` off one; ``km_begin_m`` /
  ``km_end_m`` the mileage at the piece's ends (railML 2 ``trackBegin``/``trackEnd``
  ``@absPos``, railML 3 the ``linearCoordinate`` of its intrinsic coordinates); ``length_m``
  the piece's length (railML 2 ``trackEnd/@pos`` − ``trackBegin/@pos``, railML 3
  ``@length``), else |km_end − km_begin|; ``name`` the railML name.
* ``connections`` and ``switches``: as read, track ids translated to ours (relations of
  netElements that are no tracks — meso/macro aggregates, our export's line carriers —
  dropped); a switch's ``line_code`` is its toe track's.
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from dbtools.interchange.mapping import Target
from dbtools.interchange.model import RailmlDoc
from schemas.enums import TrackKind
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES


def _our(doc: RailmlDoc, tid: str) -> str:
    t = doc.tracks.get(tid)
    return (t.db_id or tid) if t is not None else tid


def _parents(doc: RailmlDoc) -> dict[str, str]:
    """our track id → the railML track it belongs to."""
    return {p.id: t.id for t, p in doc.track_rows()}


def track_frame(doc: RailmlDoc, targets: dict[str, Target]) -> pd.DataFrame:
    rows: list[dict[str, Any]] = []
    for t, p in doc.track_rows():
        target = targets.get(t.id)
        k0 = t.mileage.km(p.offset) if t.mileage is not None else None
        k1 = t.mileage.km(p.offset + p.length) if t.mileage is not None else None
        length = p.length if p.length > 0 or k0 is None or k1 is None else abs(k1 - k0)
        kind = t.kind or (TrackKind.MAIN.value if target is not None else TrackKind.CONNECTING.value)
        rows.append(
            {
                "track_id": p.id,
                "line_code": target.line_code if target is not None else None,
                "track": target.track if target is not None else None,
                "kind": kind,
                "km_begin_m": k0,
                "km_end_m": k1,
                "length_m": length,
                "name": t.name,
            }
        )
    return pd.DataFrame(rows, columns=NETWORK_TRACKS.column_names)


def connection_frame(doc: RailmlDoc) -> pd.DataFrame:
    rows = [
        {
            "track_a": _our(doc, link.track_a),
            "end_a": link.end_a,
            "track_b": _our(doc, link.track_b),
            "end_b": link.end_b,
            "navigability": link.navigability,
            "switch_id": link.switch_id,
        }
        for link in doc.links
        if not any(t is not None and t.implied for t in (doc.tracks.get(link.track_a), doc.tracks.get(link.track_b)))
    ]
    return pd.DataFrame(rows, columns=CONNECTIONS.column_names)


def switch_frame(doc: RailmlDoc, targets: dict[str, Target]) -> pd.DataFrame:
    parents = _parents(doc)
    rows = []
    for s in doc.switches.values():
        row: dict[str, Any] = {"switch_id": s.id, "type": s.type, "name": s.name, "km_m": s.km}
        row |= {"lat": s.lat, "lon": s.lon}
        for port, (track, end) in s.ports.items():
            row[f"{port}_track"], row[f"{port}_end"] = _our(doc, track), end
        target = targets.get(parents.get(_our(doc, s.track_id or ""), s.track_id or ""))
        row |= {
            "diverging_side": s.diverging_side,
            "switch_number": s.switch_number,
            "diverging_radius_m": s.radius,
            "diverging_speed_kmh": s.speed,
            "line_code": target.line_code if target is not None else None,
        }
        rows.append(row)
    return pd.DataFrame(rows, columns=SWITCHES.column_names)
