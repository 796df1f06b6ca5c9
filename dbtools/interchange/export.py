"""``db export DB --format railml|geojson|gpkg|geoparquet|rtm-geojson --out FILE``: one
network (a DB file or a source set) in another format; the output is written atomically and
an existing one is refused without ``force``, and the source never replaced (checked before
any work).

GeoJSON and GeoPackage hold the line-grid layers (balises, feature_points, gis_points,
gis_lines: :func:`~dbtools.interchange.geojson.network_features`) and the network layers
(tracks, switches, connections, balise_groups, km_posts:
:mod:`~dbtools.interchange.network_layers`); a GeoPackage has one table per layer, GeoJSON
one FeatureCollection with a ``layer`` property (``--out`` ending in ``.geojson`` or
``.json``), one file ``LAYER.geojson`` per layer in a folder (any other ``--out``), or those
files in a zip (``--out`` ending in ``.zip``). GeoParquet keeps the line-grid layers.
``rtm-geojson``: RailTopoModel GeoJSON as tp-lib reads it (:mod:`~dbtools.interchange.rtm_export`).

``layers`` (``--layers``) keeps only the named layers (:data:`EXPORT_LAYERS`; GeoParquet:
:data:`GRID_LAYERS`); ``crs`` (``--crs EPSG:XXXX``) reprojects every layer from the network's
geodetic datum (:mod:`~dbtools.interchange.reproject`). The GeoPackage records that CRS in
``gpkg_spatial_ref_sys`` and each layer's ``srs_id``, GeoParquet in its ``geo`` metadata.
GeoJSON: RFC 7946 allows WGS 84 only, so without ``crs`` (or with EPSG:4326) the file has
no CRS member (lon/lat in the network's datum, read as WGS 84: they differ by a metre or
two); with another CRS it carries the GeoJSON 2008 member ``"crs": {"type": "name",
"properties": {"name": "urn:ogc:def:crs:EPSG::XXXX"}}``, which GDAL and QGIS read (a
strict RFC 7946 reader ignores it and takes the numbers as lon/lat), coordinates (x, y)
as :mod:`~dbtools.interchange.reproject` says. Both options only for geojson, gpkg and
geoparquet (UsageError otherwise)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

from dbtools.atomic import atomic_file, atomic_folder, check_target
from dbtools.diff import load_network
from dbtools.gis.index import network_georef
from dbtools.interchange.geojson import collection, geojson_text, network_features, write_geojson
from dbtools.interchange.geometry import WGS84
from dbtools.interchange.geometry import geodetic_epsg as lonlat_epsg
from dbtools.interchange.network_layers import LAYERS as NETWORK_LAYERS
from dbtools.network import Network
from schemas.errors import UsageError


class ExportFormat(StrEnum):
    railml = "railml"
    geojson = "geojson"
    gpkg = "gpkg"
    geoparquet = "geoparquet"
    rtm_geojson = "rtm-geojson"


#: ``--out`` endings of a single GeoJSON file; ``.zip`` a zip of per-layer files; else a folder.
GEOJSON_FILE_SUFFIXES = (".geojson", ".json")
#: The line-grid layers (:func:`~dbtools.interchange.geojson.network_features`).
GRID_LAYERS = ("balises", "feature_points", "gis_points", "gis_lines")
#: Every layer of the GeoJSON and GeoPackage export, in order.
EXPORT_LAYERS = (*GRID_LAYERS, *NETWORK_LAYERS)
#: Formats with GIS layers: ``layers`` and ``crs`` apply to them only.
LAYERED = ("geojson", "gpkg", "geoparquet")


@dataclass(frozen=True)
class GisOptions:
    """Which layers, in which CRS (EPSG code; None: the network's geodetic datum)."""

    layers: tuple[str, ...] | None = None
    crs: int | None = None


def check_gis_options(fmt: ExportFormat, options: GisOptions) -> None:
    """UsageError for ``layers``/``crs`` with a format without GIS layers, or an unknown layer."""
    if fmt.value not in LAYERED:
        if options.layers is not None or options.crs is not None:
            raise UsageError(f"--layers and --crs apply to {', '.join(LAYERED)}, not --format {fmt.value}")
        return
    known = GRID_LAYERS if fmt == ExportFormat.geoparquet else EXPORT_LAYERS
    unknown = [name for name in options.layers or () if name not in known]
    if unknown:
        raise UsageError(f"--layers: no layer {', '.join(unknown)} in --format {fmt.value}; use {', '.join(known)}")


def geodetic_epsg(network: Network) -> int:
    """EPSG code of the lat/lon datum of the network (the geodetic CRS of its metric CRS)."""
    g = network_georef(network)
    return WGS84 if g is None else lonlat_epsg(g.crs_epsg)


def export_network(
    source: Path,
    out: Path,
    fmt: ExportFormat,
    *,
    force: bool = False,
    xsd: Path | None = None,
    gis: GisOptions | None = None,
) -> dict[str, int]:
    """Write ``source`` as ``fmt`` to ``out`` (the output rule of :mod:`dbtools.atomic`:
    never over ``source`` itself); returns rows per table or layer. With ``xsd`` (railML
    only) the document is validated against that XML Schema before anything is written
    (:mod:`~dbtools.interchange.xsd`: FindingsError when it is not valid). ``gis``: the
    layers and CRS of geojson, gpkg and geoparquet (module doc)."""
    out = Path(out)
    gis = gis or GisOptions()
    if xsd is not None and fmt != ExportFormat.railml:
        raise UsageError(f"--xsd validates railML only, not --format {fmt.value}")
    check_gis_options(fmt, gis)
    inputs = [Path(source)]
    folder = fmt == ExportFormat.geojson and out.suffix.lower() not in (*GEOJSON_FILE_SUFFIXES, ".zip")
    empty = folder and out.is_dir() and not any(out.iterdir())
    check_target(out, force=force or empty, kind="folder" if folder else "file", inputs=inputs)  # before the work
    schema = None
    if xsd is not None:
        from dbtools.interchange.xsd import load_schema

        schema = load_schema(xsd)
    network, _ = load_network(Path(source))
    counts = {name: len(frame) for name, frame in network.tables.items()}
    if fmt == ExportFormat.railml:
        _write_railml(network, out, force, schema, xsd, inputs)
        return counts
    if fmt == ExportFormat.rtm_geojson:
        from dbtools.interchange.rtm_export import network_rtm_geojson

        gj, rtm_counts = network_rtm_geojson(network)
        write_geojson(out, gj, force=force, inputs=inputs)
        return rtm_counts
    features, epsg = gis_layers(network, gis, grid_only=fmt == ExportFormat.geoparquet)
    if fmt == ExportFormat.geojson:
        return _write_geojson(network, features, gis.crs, out, force or empty, inputs)
    if fmt == ExportFormat.gpkg:
        from dbtools.interchange.gpkg import write_gpkg
        from dbtools.interchange.network_layers import COLUMN_TYPES

        return write_gpkg(out, features, srs_epsg=epsg, force=force, inputs=inputs, column_types=COLUMN_TYPES)
    from dbtools.interchange.geoparquet import write_geoparquet

    write_geoparquet(out, features, srs_epsg=epsg, force=force, inputs=inputs)
    return _layers(features)


def gis_layers(network: Network, options: GisOptions, *, grid_only: bool = False) -> tuple[list[dict[str, Any]], int]:
    """The features of the chosen layers (all: :data:`EXPORT_LAYERS`, or :data:`GRID_LAYERS`
    with ``grid_only``) in the chosen CRS, and that CRS's EPSG code."""
    from dbtools.interchange.network_layers import network_layer_features, on_track

    if grid_only:
        features = network_features(network)
    else:
        features = network_features(network, on_track(network)) + network_layer_features(network)
    if options.layers is not None:
        keep = set(options.layers)
        features = [f for f in features if f["properties"].get("layer") in keep]
    source = geodetic_epsg(network)
    if options.crs is None:
        return features, source
    from dbtools.interchange.reproject import reproject

    return reproject(features, source, options.crs), options.crs


def geojson_crs(epsg: int) -> dict[str, Any]:
    """The GeoJSON 2008 ``crs`` member naming ``epsg`` (written for a CRS other than WGS 84)."""
    return {"type": "name", "properties": {"name": f"urn:ogc:def:crs:EPSG::{epsg}"}}


def _write_geojson(
    network: Network, features: list[dict[str, Any]], crs_epsg: int | None, out: Path, force: bool, inputs: list[Path]
) -> dict[str, int]:
    """One file, a folder of one file per layer, or their zip (module doc); ``crs_epsg``
    (a ``--crs`` other than WGS 84) is named in each collection's ``crs`` member."""
    crs = {"crs": geojson_crs(crs_epsg)} if crs_epsg is not None and crs_epsg != WGS84 else {}
    gj = {**collection(features, name=f"trainpos {network.meta.get('db_version', '')}".strip()), **crs}
    if out.suffix.lower() in GEOJSON_FILE_SUFFIXES:
        write_geojson(out, gj, force=force, inputs=inputs)
        return _layers(gj["features"])
    layers: dict[str, list[dict[str, Any]]] = {}
    for f in gj["features"]:
        layers.setdefault(str(f["properties"]["layer"]), []).append(f)
    files = {f"{name}.geojson": geojson_text({**collection(feats, name=name), **crs}) for name, feats in layers.items()}
    if out.suffix.lower() == ".zip":
        import zipfile

        with atomic_file(out, force=force, inputs=inputs) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
            for name, text in files.items():
                z.writestr(name, text)
    else:
        with atomic_folder(out, force=force, inputs=inputs) as tmp:
            for name, text in files.items():
                (tmp / name).write_text(text, encoding="utf-8")
    return {k: len(v) for k, v in layers.items()}


def _write_railml(network: Network, out: Path, force: bool, schema: Any, xsd: Path | None, inputs: list[Path]) -> None:
    from dbtools.interchange.railml_out import network_railml

    data = network_railml(network)
    if schema is not None and xsd is not None:
        from lxml import etree

        from dbtools.interchange.xsd import check_valid

        check_valid(schema, etree.fromstring(data).getroottree(), file=str(out), xsd=xsd, what="the railML export")
    with atomic_file(out, force=force, inputs=inputs) as tmp:
        tmp.write_bytes(data)


def _layers(features: list[dict[str, object]]) -> dict[str, int]:
    out: dict[str, int] = {}
    for f in features:
        layer = str(f["properties"].get("layer"))  # type: ignore[attr-defined]
        out[layer] = out.get(layer, 0) + 1
    return out
