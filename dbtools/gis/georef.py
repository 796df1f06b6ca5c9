"""Where a network lies and how it is measured: operating area, metric CRS and height datum.

A source set may declare them in ``network.toml`` beside its tables; ``db build`` stores
them in the DB ``meta`` (keys :data:`META_KEYS`), *declared* or *derived*:

* ``area`` — JSON ``{"lat_min", "lat_max", "lon_min", "lon_max"}`` (a box, degrees) or
  ``{"polygon": [[lon, lat], …]}``; ``area_source`` = declared | derived.
* ``metric_crs`` — ``EPSG:<code>`` of a projected CRS in metres; ``metric_crs_source``.
* ``height_datum`` — ``ellipsoidal`` or ``orthometric``; ``geoid_model`` names the geoid
  of orthometric heights (e.g. ``GSIGEO2011``). A DB without the key has ellipsoidal
  heights (what the ``gis.height_m`` column has always said).

**Derivation** (:func:`derive`), from the median (lat, lon) of the GIS points:

* inside the JGD2011 box (:data:`~schemas.tables.JAPAN_AREA`, lat 20–46°, lon 122–154°):
  the JGD2011 plane rectangular zone whose origin is nearest (zones 1–19, EPSG 6669–6687)
  and that box as the area — exactly the rules before areas could be declared;
* elsewhere: the UTM zone (WGS 84) of the median longitude, north (EPSG 326zz) or south
  (EPSG 327zz) by the median latitude — plain 6° zones, without the Norway/Svalbard
  exceptions; a national transverse Mercator (ETRS-TM35FIN EPSG:3067, NZTM EPSG:2193,
  MGA EPSG:78xx, …) is declared rather than guessed. The area is the bounding box of the
  points within :data:`DERIVED_RADIUS_M` of the median point (a point farther away is
  not part of the network's extent: it is reported, not absorbed).

One plane for the whole network: a network straddling a UTM zone border stays in the zone
of its median (transverse Mercator is still conformal there; the scale error 3° beyond a
zone edge at 45° latitude is 5·10⁻⁴, and lengths along the track are geodesic anyway).

Latitude and longitude are taken in the geodetic CRS underlying the metric CRS (JGD2011
for the JGD2011 zones, WGS 84 for UTM, ETRS89 for EPSG:3067 …): no datum transformation
is applied — GIS, survey and GNSS coordinates are assumed to be in one realisation.
Geodesic lengths use GRS80 everywhere (WGS 84 differs by 0.1 mm in the semi-minor axis; a
declared CRS on an older ellipsoid, e.g. Bessel, would be off by ~1·10⁻⁴ in length).

Heights: nothing in the suite converts between datums (no geoid model is shipped); the
GNSS code works with ellipsoidal heights, so an orthometric DB must name its geoid model
for any consumer that needs ellipsoidal heights to convert them.

**Far outside.** :meth:`Area.distance_m` is the distance from a point to the area (0
inside), in an equirectangular plane at the area's mean latitude (≈1 % — ample for the
threshold). A point more than ``tolerance_m`` (:data:`AREA_TOLERANCE_M` = 2 km: more than
any survey error or a box drawn slightly tight, less than any wrong sign, swapped
coordinates or missing decimal point) outside the area is an error and is left out of the
grid index; a point outside but within the tolerance is a warning and is used.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from dbtools.gis.geometry import GEOD, Projector, zone_epsg, zone_for
from schemas.errors import InputError
from schemas.tables import GEOREF_META_KEYS, JAPAN_AREA

F64 = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: File of a source set declaring area, CRS and heights.
NETWORK_FILE = "network.toml"
#: DB meta keys written by ``db build``.
META_KEYS = GEOREF_META_KEYS
#: A point farther than this outside the operating area is an error [m] (module doc).
AREA_TOLERANCE_M = 2000.0
#: Derived areas outside Japan: points within this of the median point [m].
DERIVED_RADIUS_M = 1_000_000.0
#: Metres per degree of latitude (mean, for the equirectangular distance).
M_PER_DEG = 111_195.0
DECLARED, DERIVED = "declared", "derived"
ELLIPSOIDAL, ORTHOMETRIC = "ellipsoidal", "orthometric"


@dataclass(frozen=True)
class Area:
    """An operating area: a lat/lon box, or a polygon of (lon, lat) vertices."""

    lat_min: float
    lat_max: float
    lon_min: float
    lon_max: float
    polygon: tuple[tuple[float, float], ...] = ()
    """(lon, lat) vertices; empty: the box itself. The box is then the polygon's bounds."""

    @classmethod
    def box(cls, lat_min: float, lat_max: float, lon_min: float, lon_max: float) -> Area:
        return cls(float(lat_min), float(lat_max), float(lon_min), float(lon_max))

    @classmethod
    def from_polygon(cls, vertices: list[tuple[float, float]]) -> Area:
        lon = [float(v[0]) for v in vertices]
        lat = [float(v[1]) for v in vertices]
        return cls(min(lat), max(lat), min(lon), max(lon), tuple(zip(lon, lat, strict=True)))

    def _shape(self) -> Any:
        import shapely

        ring = self.polygon or (
            (self.lon_min, self.lat_min),
            (self.lon_max, self.lat_min),
            (self.lon_max, self.lat_max),
            (self.lon_min, self.lat_max),
        )
        scale = math.cos(math.radians(0.5 * (self.lat_min + self.lat_max)))
        return shapely.Polygon([(lo * scale, la) for lo, la in ring]), scale

    def distance_m(self, lat: npt.ArrayLike, lon: npt.ArrayLike) -> F64:
        """Distance of each point to the area [m]: 0 inside (or on the edge), NaN for a
        non-finite coordinate (equirectangular at the area's mean latitude)."""
        la = np.atleast_1d(np.asarray(lat, dtype=float))
        lo = np.atleast_1d(np.asarray(lon, dtype=float))
        out = np.full(la.shape, np.nan)
        ok = np.isfinite(la) & np.isfinite(lo)
        with np.errstate(invalid="ignore"):
            in_box = ok & (la >= self.lat_min) & (la <= self.lat_max) & (lo >= self.lon_min) & (lo <= self.lon_max)
        out[in_box] = 0.0
        todo = np.flatnonzero(ok & (~in_box | bool(self.polygon)))
        if todo.size:  # shapely only for points outside the box, or a polygon
            import shapely

            shape, scale = self._shape()
            shapely.prepare(shape)
            pts = shapely.points(lo[todo] * scale, la[todo])
            out[todo] = shapely.distance(shape, pts) * M_PER_DEG
        return out

    def to_json(self) -> str:
        if self.polygon:
            return json.dumps({"polygon": [list(v) for v in self.polygon]})
        return json.dumps(
            {"lat_min": self.lat_min, "lat_max": self.lat_max, "lon_min": self.lon_min, "lon_max": self.lon_max}
        )

    def describe(self) -> str:
        if self.polygon:
            return f"polygon of {len(self.polygon)} vertices within lat {self.lat_min:g}–{self.lat_max:g}°"
        return f"lat {self.lat_min:g}–{self.lat_max:g}°, lon {self.lon_min:g}–{self.lon_max:g}°"


JAPAN = Area.box(*JAPAN_AREA)


@dataclass(frozen=True)
class Georef:
    """Operating area, metric CRS and height datum of one network (module doc)."""

    area: Area
    crs_epsg: int
    area_source: str = DERIVED
    crs_source: str = DERIVED
    height_datum: str = ELLIPSOIDAL
    geoid_model: str | None = None

    def to_meta(self) -> dict[str, str]:
        meta = {
            "area": self.area.to_json(),
            "area_source": self.area_source,
            "metric_crs": f"EPSG:{self.crs_epsg}",
            "metric_crs_source": self.crs_source,
            "height_datum": self.height_datum,
        }
        if self.geoid_model:
            meta["geoid_model"] = self.geoid_model
        return meta

    @property
    def heights(self) -> str:
        """``ellipsoidal`` or ``orthometric (GEOID)``, for messages."""
        return f"{ORTHOMETRIC} ({self.geoid_model})" if self.height_datum == ORTHOMETRIC else ELLIPSOIDAL


def utm_epsg(lat: float, lon: float) -> int:
    """EPSG code of the WGS 84 / UTM zone holding (lat, lon): 326zz north, 327zz south."""
    zone = math.floor((lon + 180.0) / 6.0) % 60 + 1
    return (32600 if lat >= 0 else 32700) + zone


def _median(lat: F64, lon: F64) -> tuple[float, float] | None:
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    if not ok.any():
        return None
    return float(np.median(lat[ok])), float(np.median(lon[ok]))


def derive(lat: npt.ArrayLike, lon: npt.ArrayLike) -> Georef | None:
    """Area and metric CRS from the points (module doc, "Derivation"); None without points."""
    la, lo = np.asarray(lat, dtype=float), np.asarray(lon, dtype=float)
    mid = _median(la, lo)
    if mid is None:
        return None
    if JAPAN.distance_m(mid[0], mid[1])[0] == 0.0:
        return Georef(JAPAN, zone_epsg(zone_for(*mid)))
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(la) & np.isfinite(lo) & (np.abs(la) <= 90) & (np.abs(lo) <= 180)
    _, _, dist = GEOD.inv(np.full(int(ok.sum()), mid[1]), np.full(int(ok.sum()), mid[0]), lo[ok], la[ok])
    near = np.asarray(dist) <= DERIVED_RADIUS_M
    area = Area.box(la[ok][near].min(), la[ok][near].max(), lo[ok][near].min(), lo[ok][near].max())
    return Georef(area, utm_epsg(*mid))


def projector_for_points(lat: npt.ArrayLike, lon: npt.ArrayLike) -> Projector:
    """The projection of a set of points by the one policy of :func:`derive` (a JGD2011
    zone in Japan, UTM elsewhere); ValueError without a finite point."""
    g = derive(lat, lon)
    if g is None:
        raise ValueError("no finite point to choose a projection for")
    return Projector.from_epsg(g.crs_epsg)


def _crs_of(value: object, where: str, path: Path | None) -> int:
    """EPSG code of a projected CRS in metres ("EPSG:32632" or 32632)."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    text = str(value).strip()
    code = text.split(":", 1)[1] if text.upper().startswith("EPSG:") else text
    try:
        crs = CRS.from_epsg(int(code))
    except (ValueError, CRSError) as exc:
        raise InputError(f"{where}: '{value}' is not an EPSG code known to PROJ", path=path) from exc
    unit = crs.axis_info[0].unit_name if crs.axis_info else ""
    if not crs.is_projected or unit not in ("metre", "meter"):
        raise InputError(f"{where}: EPSG:{code} is not a projected CRS in metres", path=path)
    return int(code)


def _area_of(value: object, path: Path | None) -> Area:
    if not isinstance(value, Mapping):
        raise InputError("area: expected a table with lat_min, lat_max, lon_min, lon_max or polygon", path=path)
    if "polygon" in value:
        verts = value["polygon"]
        ok = isinstance(verts, list) and len(verts) >= 3 and all(isinstance(v, list) and len(v) == 2 for v in verts)
        if not ok:
            raise InputError("area.polygon: expected at least three [lon, lat] pairs", path=path)
        area = Area.from_polygon([(float(v[0]), float(v[1])) for v in verts])
    else:
        missing = [k for k in ("lat_min", "lat_max", "lon_min", "lon_max") if k not in value]
        if missing:
            raise InputError(f"area: missing {', '.join(missing)}", path=path)
        try:
            area = Area.box(*(float(value[k]) for k in ("lat_min", "lat_max", "lon_min", "lon_max")))
        except (TypeError, ValueError) as exc:
            raise InputError("area: lat_min, lat_max, lon_min, lon_max must be numbers [deg]", path=path) from exc
    if not (-90 <= area.lat_min < area.lat_max <= 90 and -180 <= area.lon_min < area.lon_max <= 180):
        raise InputError(f"area: {area.describe()} is not a box with min < max inside ±90°/±180°", path=path)
    return area


def _heights_of(value: Mapping[str, Any], path: Path | None) -> tuple[str, str | None]:
    datum = str(value.get("height_datum", ELLIPSOIDAL))
    geoid = value.get("geoid_model")
    if datum not in (ELLIPSOIDAL, ORTHOMETRIC):
        raise InputError(f"height_datum: '{datum}' is neither '{ELLIPSOIDAL}' nor '{ORTHOMETRIC}'", path=path)
    if datum == ORTHOMETRIC and not geoid:
        raise InputError("height_datum 'orthometric' needs geoid_model (e.g. 'GSIGEO2011', 'EGM2008')", path=path)
    return datum, (str(geoid) if datum == ORTHOMETRIC else None)


def read_declaration(path: Path) -> dict[str, str]:
    """``network.toml`` as meta entries (only what it declares). InputError naming the file
    and key on anything it cannot use.

    Keys: ``metric_crs = "EPSG:32632"``; ``height_datum = "ellipsoidal" | "orthometric"``,
    ``geoid_model = "…"``; ``[area]`` with ``lat_min``, ``lat_max``, ``lon_min``,
    ``lon_max`` [deg] or ``polygon = [[lon, lat], …]``. ``[csv]`` (the convention of the
    source files, :func:`dbtools.sources.declared_locale`) is no meta entry.
    """
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", path=path) from exc
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from exc
    unknown = sorted(set(data) - {"area", "metric_crs", "height_datum", "geoid_model", "csv"})
    if unknown:
        raise InputError(
            f"unknown key(s) {', '.join(unknown)} (known: area, metric_crs, height_datum, geoid_model, csv)", path=path
        )
    meta: dict[str, str] = {}
    if "area" in data:
        meta.update(area=_area_of(data["area"], path).to_json(), area_source=DECLARED)
    if "metric_crs" in data:
        meta.update(metric_crs=f"EPSG:{_crs_of(data['metric_crs'], 'metric_crs', path)}", metric_crs_source=DECLARED)
    if "height_datum" in data or "geoid_model" in data:
        datum, geoid = _heights_of(data, path)
        meta["height_datum"] = datum
        if geoid:
            meta["geoid_model"] = geoid
    return meta


def write_declaration(meta: Mapping[str, str], path: Path) -> bool:
    """Write the declared entries of ``meta`` as ``network.toml``; False (nothing written)
    when nothing is declared."""
    lines: list[str] = []
    if meta.get("metric_crs_source") == DECLARED and "metric_crs" in meta:
        lines.append(f'metric_crs = "{meta["metric_crs"]}"')
    if "height_datum" in meta and meta.get("height_datum") != ELLIPSOIDAL:
        lines.append(f'height_datum = "{meta["height_datum"]}"')
        if meta.get("geoid_model"):
            lines.append(f'geoid_model = "{meta["geoid_model"]}"')
    if meta.get("area_source") == DECLARED and "area" in meta:
        area = json.loads(meta["area"])
        lines.append("\n[area]")
        if "polygon" in area:
            lines.append("polygon = " + json.dumps(area["polygon"]))
        else:
            lines += [f"{k} = {float(area[k])!r}" for k in ("lat_min", "lat_max", "lon_min", "lon_max")]
    if not lines:
        return False
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return True


def georef_of(meta: Mapping[str, str], lat: npt.ArrayLike, lon: npt.ArrayLike, origin: str = "") -> Georef | None:
    """The network's georeference: what ``meta`` states (declared, or derived and stored at
    build), the rest derived from the points; None when nothing can be derived."""
    path = Path(origin) if origin else None
    derived = None if "area" in meta and "metric_crs" in meta else derive(lat, lon)
    if derived is None and not ("area" in meta and "metric_crs" in meta):
        return None
    if "area" in meta:
        area, area_source = _area_of(json.loads(meta["area"]), path), meta.get("area_source", DECLARED)
    else:
        assert derived is not None
        area, area_source = derived.area, DERIVED
    if "metric_crs" in meta:
        crs, crs_source = _crs_of(meta["metric_crs"], "meta metric_crs", path), meta.get("metric_crs_source", DECLARED)
    else:
        assert derived is not None
        crs, crs_source = derived.crs_epsg, DERIVED
    datum, geoid = _heights_of(meta, path)
    return Georef(area, crs, area_source, crs_source, datum, geoid)
