"""The reference answer of a ``candidates`` cell (:func:`fieldlogs.pipeline.claims.claims`
makes them all at once): the compact JSON encoder's text of the cycle's objects, made cycle by
cycle as the cell is specified."""

from __future__ import annotations

import json

import numpy as np

from fieldlogs.pipeline.claims import Entry


def candidates_text(ents: list[Entry], i: int) -> str:
    """The ``candidates`` cell of cycle ``i`` of the entries present on it: a JSON list of objects
    ``track_id``, ``pos_m``, ``km_m`` (null off a line) and ``margin_m``, rounded to mm (null when
    not finite); one per track (the first)."""
    items: dict[str, dict[str, object]] = {}
    for e in ents:
        if e.track_id not in items:
            items[e.track_id] = {"track_id": e.track_id, "pos_m": _r(e.pos[i]), "km_m": _r(e.km[i])}
            items[e.track_id]["margin_m"] = _r(e.margin[i])
    return json.dumps(list(items.values()), separators=(",", ":"))


def _r(x: float) -> float | None:
    return round(float(x), 3) if np.isfinite(x) else None
