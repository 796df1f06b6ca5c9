"""GeoParquet 1.1 of the GeoJSON layers: one table, a ``layer`` column, every property a
column, ``geometry`` as WKB (:mod:`.wkb`), and the ``geo`` file metadata (version,
primary column, encoding WKB, geometry types, CRS as PROJJSON, bbox). pyarrow.parquet is
imported on first use.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from dbtools.atomic import atomic_file
from dbtools.interchange.wkb import envelope, wkb

GEOPARQUET_VERSION = "1.1.0"


def _column(values: list[Any]) -> list[Any]:
    """Mixed types in one column (numbers and text across layers) become text."""
    kinds = {type(v) for v in values if v is not None}
    if len(kinds) > 1 and not kinds <= {int, float}:
        return [None if v is None else str(v) for v in values]
    return values


def write_geoparquet(
    path: Path,
    features: Sequence[dict[str, Any]],
    *,
    srs_epsg: int = 4326,
    force: bool = False,
    inputs: Sequence[Path | str] = (),
) -> int:
    import pyarrow as pa
    import pyarrow.parquet as pq
    from pyproj import CRS

    cols = sorted({k for f in features for k in f["properties"]})
    data = {c: _column([f["properties"].get(c) for f in features]) for c in cols}
    frame = pd.DataFrame(data)
    geoms = [f["geometry"] for f in features]
    table = pa.Table.from_pandas(frame, preserve_index=False)
    table = table.append_column("geometry", pa.array([None if g is None else wkb(g) for g in geoms], type=pa.binary()))
    boxes = [envelope(g) for g in geoms if g is not None]
    geo = {
        "version": GEOPARQUET_VERSION,
        "primary_column": "geometry",
        "columns": {
            "geometry": {
                "encoding": "WKB",
                "geometry_types": sorted(
                    {
                        g["type"] + (" Z" if g["type"] == "Point" and len(g["coordinates"]) == 3 else "")
                        for g in geoms
                        if g
                    }
                ),
                "crs": json.loads(CRS.from_epsg(srs_epsg).to_json()),
                **(
                    {
                        "bbox": [
                            min(b[0] for b in boxes),
                            min(b[2] for b in boxes),
                            max(b[1] for b in boxes),
                            max(b[3] for b in boxes),
                        ]
                    }
                    if boxes
                    else {}
                ),
            }
        },
    }
    meta = dict(table.schema.metadata or {})
    meta[b"geo"] = json.dumps(geo).encode()
    table = table.replace_schema_metadata(meta)
    with atomic_file(Path(path), force=force, inputs=inputs) as tmp:
        pq.write_table(table, tmp)
    return len(features)
