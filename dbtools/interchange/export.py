"""``db export DB --format railml|geojson|gpkg|geoparquet --out FILE``: one network (a DB
file or a source set) in another format; the output is written atomically and an existing
one is refused without ``force``, and the source never replaced (checked before any work)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Any

from dbtools.atomic import atomic_file, check_target
from dbtools.diff import load_network
from dbtools.gis.index import network_georef
from dbtools.interchange.geojson import network_features, network_geojson, write_geojson
from dbtools.interchange.geometry import WGS84
from dbtools.interchange.geometry import geodetic_epsg as lonlat_epsg
from dbtools.network import Network
from schemas.errors import UsageError


class ExportFormat(StrEnum):
    railml = "railml"
    geojson = "geojson"
    gpkg = "gpkg"
    geoparquet = "geoparquet"


def geodetic_epsg(network: Network) -> int:
    """EPSG code of the lat/lon datum of the network (the geodetic CRS of its metric CRS)."""
    g = network_georef(network)
    return WGS84 if g is None else lonlat_epsg(g.crs_epsg)


def export_network(
    source: Path, out: Path, fmt: ExportFormat, *, force: bool = False, xsd: Path | None = None
) -> dict[str, int]:
    """Write ``source`` as ``fmt`` to ``out`` (the output rule of :mod:`dbtools.atomic`:
    never over ``source`` itself); returns rows per table or layer. With ``xsd`` (railML
    only) the document is validated against that XML Schema before anything is written
    (:mod:`~dbtools.interchange.xsd`: FindingsError when it is not valid)."""
    out = Path(out)
    if xsd is not None and fmt != ExportFormat.railml:
        raise UsageError(f"--xsd validates railML only, not --format {fmt.value}")
    inputs = [Path(source)]
    check_target(out, force=force, kind="file", inputs=inputs)  # before the work
    schema = None
    if xsd is not None:
        from dbtools.interchange.xsd import load_schema

        schema = load_schema(xsd)
    network, _ = load_network(Path(source))
    counts = {name: len(frame) for name, frame in network.tables.items()}
    if fmt == ExportFormat.railml:
        _write_railml(network, out, force, schema, xsd, inputs)
        return counts
    if fmt == ExportFormat.geojson:
        gj = network_geojson(network)
        write_geojson(out, gj, force=force, inputs=inputs)
        return _layers(gj["features"])
    features = network_features(network)
    if fmt == ExportFormat.gpkg:
        from dbtools.interchange.gpkg import write_gpkg

        return write_gpkg(out, features, srs_epsg=geodetic_epsg(network), force=force, inputs=inputs)
    from dbtools.interchange.geoparquet import write_geoparquet

    write_geoparquet(out, features, srs_epsg=geodetic_epsg(network), force=force, inputs=inputs)
    return _layers(features)


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
