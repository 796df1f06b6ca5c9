"""GeoPackage (OGC 12-128, version 1.3) of the GeoJSON layers, for QGIS: one feature table per
layer (balises, feature_points, gis_points, gis_lines …), written with SQLite through
:func:`dbtools.database.write_sqlite` — the format is a plain SQLite file, so no GDAL-based
library (pyogrio, fiona: large binary wheels) is needed.

What a reader requires and this writes: ``PRAGMA application_id`` 0x47504B47 ("GPKG") and
``user_version`` 10300 (GeoPackage 1.3.0: GDAL 3.6 — a QGIS LTR's, issue 33 — accepts 102xx
and 103xx silently and warns that a 1.4 file "may be only partially supported"; newer GDAL
reads 1.2–1.4; the tables written here are the same in 1.3 and 1.4);
``gpkg_spatial_ref_sys`` with the three mandatory rows (4326, −1, 0) plus the CRS of the
layers (the network's geodetic CRS, or the export's ``--crs``; WKT from PROJ);
``gpkg_contents`` (one ``features`` row per layer with its bounding box);
``gpkg_geometry_columns``; each table an ``fid INTEGER PRIMARY KEY AUTOINCREMENT``, a
``geom`` BLOB in GeoPackage binary (:mod:`.wkb`) and one column per property (INTEGER, REAL
or TEXT by its values).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from dbtools.database import write_sqlite
from dbtools.interchange.wkb import envelope, gpkg_geometry

APPLICATION_ID = 0x47504B47
#: GeoPackage 1.3.0 (module doc: read without a warning by GDAL 3.6 and newer).
USER_VERSION = 10300
_SRS = [
    ("Undefined cartesian SRS", -1, "NONE", -1, "undefined", "undefined cartesian coordinate reference system"),
    ("Undefined geographic SRS", 0, "NONE", 0, "undefined", "undefined geographic coordinate reference system"),
]


def _wkt(epsg: int) -> str:
    from pyproj import CRS

    return str(CRS.from_epsg(epsg).to_wkt("WKT1_GDAL"))


def _crs_name(epsg: int) -> str:
    from pyproj import CRS

    return str(CRS.from_epsg(epsg).name)


def _sql_type(values: Iterable[Any]) -> str:
    vals = [v for v in values if v is not None]
    if vals and all(isinstance(v, bool | int) for v in vals):
        return "INTEGER"
    if vals and all(isinstance(v, int | float) and not isinstance(v, bool) for v in vals):
        return "REAL"
    return "TEXT"


def _geometry_type(features: Sequence[dict[str, Any]]) -> str:
    kinds = {f["geometry"]["type"] for f in features if f["geometry"] is not None}
    return kinds.pop().upper() if len(kinds) == 1 else "GEOMETRY"


def _layer(
    name: str, features: list[dict[str, Any]], srs_id: int, now: str, declared: Mapping[str, str]
) -> list[tuple[str, Any]]:
    cols = sorted({k for f in features for k in f["properties"] if k != "layer"})
    types = {c: declared.get(c) or _sql_type(f["properties"].get(c) for f in features) for c in cols}
    ddl = ", ".join(f'"{c}" {types[c]}' for c in cols)
    boxes = [envelope(f["geometry"]) for f in features if f["geometry"] is not None]
    bbox = (
        (min(b[0] for b in boxes), min(b[2] for b in boxes), max(b[1] for b in boxes), max(b[3] for b in boxes))
        if boxes
        else (None,) * 4
    )
    has_z = int(
        any(
            f["geometry"] and len(f["geometry"]["coordinates"]) == 3
            for f in features
            if f["geometry"] and f["geometry"]["type"] == "Point"
        )
    )
    marks = ", ".join("?" * (len(cols) + 1))
    rows = [
        (gpkg_geometry(f["geometry"], srs_id), *(_value(f["properties"].get(c), types[c]) for c in cols))
        for f in features
    ]
    names = ", ".join(["geom", *(f'"{c}"' for c in cols)])
    return [
        (
            f'CREATE TABLE "{name}" (fid INTEGER PRIMARY KEY AUTOINCREMENT NOT NULL, geom BLOB'
            + (f", {ddl})" if ddl else ")"),
            None,
        ),
        (f'INSERT INTO "{name}" ({names}) VALUES ({marks})', rows),
        (
            "INSERT INTO gpkg_contents VALUES (?, 'features', ?, '', ?, ?, ?, ?, ?, ?)",
            [(name, name, now, *bbox, srs_id)],
        ),
        (
            "INSERT INTO gpkg_geometry_columns VALUES (?, 'geom', ?, ?, ?, 0)",
            [(name, _geometry_type(features), srs_id, has_z)],
        ),
    ]


def _value(v: Any, sql_type: str) -> Any:
    if v is None or sql_type != "TEXT" or isinstance(v, str):
        return v
    return str(v)


def write_gpkg(
    path: Path,
    features: Sequence[dict[str, Any]],
    *,
    srs_epsg: int = 4326,
    force: bool = False,
    inputs: Sequence[Path | str] = (),
    column_types: Mapping[str, Mapping[str, str]] | None = None,
) -> dict[str, int]:
    """One GeoPackage with a table per ``layer`` property; returns rows per layer. A
    column's SQL type is ``column_types[layer][column]`` where given (a column of nulls keeps
    its type: REAL for a switch number nobody knows), else from its values."""
    layers: dict[str, list[dict[str, Any]]] = {}
    for f in features:
        layers.setdefault(str(f["properties"].get("layer", "features")), []).append(f)
    now = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.000Z")
    srs = [
        (
            "WGS 84 geodetic",
            4326,
            "EPSG",
            4326,
            _wkt(4326),
            "longitude/latitude coordinates in decimal degrees on the WGS 84 spheroid",
        ),
        *_SRS,
    ]
    if srs_epsg != 4326:
        srs.append((f"EPSG:{srs_epsg}", srs_epsg, "EPSG", srs_epsg, _wkt(srs_epsg), _crs_name(srs_epsg)))
    script: list[tuple[str, Any]] = [
        (
            "CREATE TABLE gpkg_spatial_ref_sys (srs_name TEXT NOT NULL, srs_id INTEGER PRIMARY KEY, "
            "organization TEXT NOT NULL, "
            "organization_coordsys_id INTEGER NOT NULL, definition TEXT NOT NULL, description TEXT)",
            None,
        ),
        ("INSERT INTO gpkg_spatial_ref_sys VALUES (?, ?, ?, ?, ?, ?)", srs),
        (
            "CREATE TABLE gpkg_contents (table_name TEXT NOT NULL PRIMARY KEY, data_type TEXT NOT "
            "NULL, identifier TEXT UNIQUE, "
            "description TEXT DEFAULT '', last_change DATETIME NOT NULL DEFAULT "
            "(strftime('%Y-%m-%dT%H:%M:%fZ','now')), "
            "min_x DOUBLE, min_y DOUBLE, max_x DOUBLE, max_y DOUBLE, srs_id INTEGER, "
            "CONSTRAINT fk_gc_r_srs_id FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys(srs_id))",
            None,
        ),
        (
            "CREATE TABLE gpkg_geometry_columns (table_name TEXT NOT NULL, column_name TEXT NOT "
            "NULL, geometry_type_name TEXT NOT NULL, "
            "srs_id INTEGER NOT NULL, z TINYINT NOT NULL, m TINYINT NOT NULL, CONSTRAINT "
            "pk_geom_cols PRIMARY KEY (table_name, column_name), "
            "CONSTRAINT fk_gc_tn FOREIGN KEY (table_name) REFERENCES gpkg_contents(table_name), "
            "CONSTRAINT fk_gc_srs FOREIGN KEY (srs_id) REFERENCES gpkg_spatial_ref_sys (srs_id))",
            None,
        ),
    ]
    for name, feats in layers.items():
        script += _layer(name, feats, srs_epsg, now, (column_types or {}).get(name, {}))
    write_sqlite(
        path,
        script,
        pragmas=(f"application_id={APPLICATION_ID}", f"user_version={USER_VERSION}"),
        force=force,
        inputs=inputs,
    )
    return {k: len(v) for k, v in layers.items()}
