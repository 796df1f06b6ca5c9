"""GeoJSON (RFC 7946) for QGIS: the network, GIS-verification results and possession alarms.

RFC 7946: a ``FeatureCollection``; coordinates ``[lon, lat]`` (height as a third value
where known) in WGS 84 — our lat/lon are in the geodetic datum of the network's metric CRS
(JGD2011, ETRS89, WGS 84), which differ from WGS 84 by at most a metre or two; no datum
shift is applied, as everywhere in the suite. Every feature has a ``layer`` property
(``balises``, ``feature_points``, ``gis_points``, ``gis_lines``, ``defects``, ``cells``,
``proposal``, ``alarms``, ``possessions``, ``balise_moves``, ``features`` …) so one file can be split by layer in QGIS.

Things placed by kilometrage (balises, feature points, defects, alarms) get their position
from the GIS grid of their line and track by linear interpolation between the 20 m points
(:class:`GridLocator`); outside the grid their geometry is ``null`` (RFC 7946 §3.2 allows it).

The writer (:func:`write_geojson`) and the builders (:func:`feature`, :func:`point`,
:func:`line_string`, :func:`frame_points`) are meant for any command that lays results
over the GIS (``gis verify``, ``possession check``, the survey: :func:`survey_geojson`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.atomic import atomic_file
from dbtools.network import Network
from schemas.jsonable import jsonable

Geometry = dict[str, Any] | None


def point(lon: float, lat: float, height: float | None = None) -> Geometry:
    if not (math.isfinite(lon) and math.isfinite(lat)):
        return None
    coords = [float(lon), float(lat)] + ([float(height)] if height is not None and math.isfinite(height) else [])
    return {"type": "Point", "coordinates": coords}


def line_string(coords: Sequence[Sequence[float]]) -> Geometry:
    pts = [[float(c[0]), float(c[1])] for c in coords if math.isfinite(c[0]) and math.isfinite(c[1])]
    return {"type": "LineString", "coordinates": pts} if len(pts) >= 2 else None


def feature(geometry: Geometry, properties: Mapping[str, Any], ident: str | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "Feature", "geometry": geometry, "properties": jsonable(dict(properties), 9)}
    if ident is not None:
        out["id"] = ident
    return out


def collection(features: Iterable[dict[str, Any]], name: str | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "FeatureCollection", "features": list(features)}
    if name:
        out["name"] = name
    return out


def geojson_text(data: Mapping[str, Any]) -> str:
    """A FeatureCollection as the text of a file (UTF-8, no NaN: RFC 7946 is JSON)."""
    return json.dumps(data, ensure_ascii=False, allow_nan=False) + "\n"


def write_geojson(
    path: Path, data: Mapping[str, Any], *, force: bool = False, inputs: Iterable[Path | str] = ()
) -> Path:
    """Write a FeatureCollection atomically (RefusedError for an existing file without force)."""
    with atomic_file(Path(path), force=force, inputs=inputs) as tmp:  # the output rule (dbtools.atomic)
        tmp.write_text(geojson_text(data), encoding="utf-8")
    return Path(path)


def frame_points(
    frame: pd.DataFrame, layer: str, *, lon: str = "lon", lat: str = "lat", height: str | None = None
) -> list[dict[str, Any]]:
    """One Point feature per row (lon/lat columns), every other column a property."""
    props = [c for c in frame.columns if c not in (lon, lat)]
    out = []
    for rec in frame.to_dict("records"):
        h = rec.get(height) if height else None
        geom = point(_num(rec[lon]), _num(rec[lat]), None if h is None or pd.isna(h) else float(h))
        out.append(feature(geom, {"layer": layer, **{c: _clean(rec[c]) for c in props}}))
    return out


def _num(v: Any) -> float:
    return float("nan") if v is None or pd.isna(v) else float(v)


def _clean(v: Any) -> Any:
    if v is None or (not isinstance(v, str | bytes | list | dict) and pd.isna(v)):
        return None
    return v.item() if isinstance(v, np.generic) else v


class GridLocator:
    """lon/lat (and the grid polyline) of (line, track, km) from a network's GIS grid."""

    def __init__(self, network: Network) -> None:
        self.tracks: dict[tuple[str, str], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        gis = network.gis.sort_values(["line_code", "track", "km_m"])
        for (line, track), g in gis.groupby(["line_code", "track"], sort=True):
            self.tracks[(str(line), str(track))] = (
                g["km_m"].to_numpy(dtype=float),
                g["lon"].to_numpy(dtype=float),
                g["lat"].to_numpy(dtype=float),
            )

    def at(self, line: Any, track: Any, km: Any) -> tuple[float, float] | None:
        t = self.tracks.get((str(line), str(track)))
        if t is None or km is None or pd.isna(km) or not t[0][0] <= float(km) <= t[0][-1]:
            return None
        return float(np.interp(km, t[0], t[1])), float(np.interp(km, t[0], t[2]))

    def between(self, line: Any, track: Any, km0: float, km1: float) -> list[tuple[float, float]]:
        t = self.tracks.get((str(line), str(track)))
        if t is None:
            return []
        lo, hi = sorted((float(km0), float(km1)))
        inside = (t[0] > lo) & (t[0] < hi)
        ends = [self.at(line, track, k) for k in (lo, hi)]
        mid = list(zip(t[1][inside].tolist(), t[2][inside].tolist(), strict=True))
        return [p for p in [ends[0], *mid, ends[1]] if p is not None]

    def point_at(self, line: Any, track: Any, km: Any) -> Geometry:
        p = self.at(line, track, km)
        return None if p is None else point(*p)

    @classmethod
    def along_tracks(cls, network: Network) -> GridLocator:
        """The same look-ups on the ``track_points`` grids: keyed (track_id, ""), the
        position being the distance along the track from its begin (``pos_m``)."""
        loc = cls.__new__(cls)
        loc.tracks = {}
        tp = network.track_points.sort_values(["track_id", "pos_m"])
        for tid, g in tp.groupby(tp["track_id"].astype(str), sort=True):
            loc.tracks[(str(tid), "")] = (
                g["pos_m"].to_numpy(dtype=float),
                g["lon"].to_numpy(dtype=float),
                g["lat"].to_numpy(dtype=float),
            )
        return loc


def network_features(network: Network, on_track: Callable[[Any, Any], Geometry] | None = None) -> list[dict[str, Any]]:
    """Balises, feature points, GIS points and one GIS line per line/track. ``on_track``
    (track_id, km) places a balise that lies on no line grid but names its track."""
    loc = GridLocator(network)
    out: list[dict[str, Any]] = []
    for rec in network.balises.to_dict("records"):
        geom = loc.point_at(rec["line_code"], rec["track"], rec["km_actual_m"])
        if geom is None and on_track is not None and _clean(rec.get("track_id")) is not None:
            geom = on_track(rec["track_id"], rec["km_actual_m"])
        props = {"layer": "balises", **{str(k): _clean(v) for k, v in rec.items()}}
        out.append(feature(geom, props, str(rec["balise_id"])))
    for rec in network.feature_points.to_dict("records"):
        geom = loc.point_at(rec["line_code"], rec["track"], rec["km_m"])
        out.append(feature(geom, {"layer": "feature_points", **{str(k): _clean(v) for k, v in rec.items()}}))
    out += frame_points(network.gis, "gis_points", height="height_m")
    for (line, track), (km, lon, lat) in loc.tracks.items():
        props = {"layer": "gis_lines", "line_code": line, "track": track, "km_from_m": km[0], "km_to_m": km[-1]}
        out.append(feature(line_string(list(zip(lon, lat, strict=True))), props))
    return out


def network_geojson(network: Network, on_track: Callable[[Any, Any], Geometry] | None = None) -> dict[str, Any]:
    return collection(
        network_features(network, on_track), name=f"trainpos {network.meta.get('db_version', '')}".strip()
    )


def _km_features(loc: GridLocator, frame: pd.DataFrame, layer: str, along: str = "km") -> list[dict[str, Any]]:
    """A LineString along the grid from km_from_m to km_to_m for every row (``along`` "pos":
    from pos_from_m to pos_to_m along its track_id's track points)."""
    out = []
    for rec in frame.to_dict("records"):
        if along == "km":
            coords = loc.between(rec["line_code"], rec["track"], rec["km_from_m"], rec["km_to_m"])
        else:
            coords = loc.between(rec["track_id"], "", rec["pos_from_m"], rec["pos_to_m"])
        out.append(feature(line_string(coords), {"layer": layer, **{str(k): _clean(v) for k, v in rec.items()}}))
    return out


def _verification_features(loc: GridLocator, verification: Any, along: str = "km") -> list[dict[str, Any]]:
    feats = _km_features(loc, verification.defects, "defects", along)
    feats += _km_features(loc, verification.cells, "cells", along)
    feats += _km_features(loc, verification.km_defects, "km_defects", along)
    for rec in verification.proposal.to_dict("records"):
        props = {"layer": "proposal", **{str(k): _clean(v) for k, v in rec.items()}}
        feats.append(feature(point(_num(rec["lon"]), _num(rec["lat"])), props))
        move = line_string([(_num(rec["lon"]), _num(rec["lat"])), (_num(rec["lon_new"]), _num(rec["lat_new"]))])
        feats.append(feature(move, {**props, "layer": "proposal_moves"}))
    return feats


def verification_geojson(network: Network, verification: Any, track_points: Any = None) -> dict[str, Any]:
    """``gis verify`` results: defects, along-track defects (``km_defects``) and cells (with
    their mean offset, the residual) as lines along the grid, proposed moves as points at the
    old position with the new one as a property and a short line from old to new; every
    feature carries its ``track_id``. ``track_points``: the verification of the tracks off a
    line, the same layers along their track points (``pos_from_m``, ``pos_to_m``, ``pos_m``
    in the place of km)."""
    feats = _verification_features(GridLocator(network), verification)
    if track_points is not None:
        feats += _verification_features(GridLocator.along_tracks(network), track_points, "pos")
    return collection(feats, name="gis verify")


def possession_geojson(network: Network, report: Mapping[str, Any], possessions: Sequence[Any]) -> dict[str, Any]:
    """``possession check`` results (its JSON shape) and the plan's sections: alarms and
    notices as points at their km on the possession's line and track, sections as lines."""
    loc = GridLocator(network)
    lines = {str(p.work_no): str(p.line_code) for p in possessions}
    feats = []
    for p in possessions:
        props = {
            "layer": "possessions",
            "work_no": p.work_no,
            "line_code": p.line_code,
            "track": p.track,
            "km_from_m": p.km_from_m,
            "km_to_m": p.km_to_m,
        }
        feats.append(feature(line_string(loc.between(p.line_code, p.track, p.km_from_m, p.km_to_m)), props))
    for run in report.get("runs", []):
        for layer in ("alarms", "notices"):
            for a in run.get(layer, []):
                line = lines.get(str(a.get("work_no")))
                geom = loc.point_at(line, a.get("track"), a.get("km_m")) if line is not None else None
                props = {"layer": layer, "run": run.get("run"), "run_id": run.get("run_id"), "line_code": line}
                props.update({k: v for k, v in a.items() if k != "evidence"})
                props["evidence"] = json.dumps(a.get("evidence", {}), ensure_ascii=False)
                feats.append(feature(geom, props))
    return collection(feats, name="possession check")


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    return [{str(k): _clean(v) for k, v in rec.items()} for rec in frame.to_dict("records")]


def _balise_features(loc: GridLocator, balises: pd.DataFrame) -> list[dict[str, Any]]:
    """A Point at the DB km per balise; the runs' place (km_surveyed_m = km_db_m − residual_m,
    the residual being DB km − runs' km) as lon/lat properties, and for a moved balise a
    ``balise_moves`` line along the grid from the DB km to the runs' km."""
    out = []
    for rec in _records(balises):
        there = loc.at(rec["line_code"], rec["track"], rec["km_surveyed_m"])
        lon_s, lat_s = there if there is not None else (None, None)
        props = {"layer": "balises", **rec, "lon_surveyed": lon_s, "lat_surveyed": lat_s}
        out.append(feature(loc.point_at(rec["line_code"], rec["track"], rec["km_db_m"]), props, str(rec["balise_id"])))
        if rec["status"] == "moved" and there is not None:
            move = line_string(loc.between(rec["line_code"], rec["track"], rec["km_db_m"], rec["km_surveyed_m"]))
            out.append(feature(move, {**props, "layer": "balise_moves"}))
    return out


def _candidate_features(loc: GridLocator, candidates: pd.DataFrame) -> list[dict[str, Any]]:
    """Telegrams the DB does not know: Points at the runs' km, status ``candidate``."""
    out = []
    for rec in _records(candidates):
        props = {"layer": "balises", "balise_id": rec["candidate_id"], "status": "candidate", **rec}
        out.append(feature(loc.point_at(rec["line_code"], rec["track"], rec["km_m"]), props))
    return out


def _span(loc: GridLocator, rec: Mapping[str, Any], suffix: str) -> Geometry:
    """The curve from its entry to its exit km (``entry_km{suffix}``, ``exit_km{suffix}``)."""
    a, b = rec.get(f"entry_km{suffix}"), rec.get(f"exit_km{suffix}")
    if a is None or b is None:
        return None
    return line_string(loc.between(rec["line_code"], rec["track"], float(a), float(b)))


def _curve_features(
    loc: GridLocator, features: pd.DataFrame, tracks: GridLocator | None = None
) -> list[dict[str, Any]]:
    """Curves (a DB feature point's entry to exit, or a new curve's as the runs place it) as
    lines along the grid, layer ``features`` with its status; moved and new ones also as the
    runs place them (layer ``feature_proposals``, the position ``--propose`` writes). A row
    with no line (a curve of ``track_feature_points``, its entry/exit the pos along its
    track) is drawn along its track's ``track_points`` (``tracks``)."""
    out = []
    for rec in _records(features):
        props = {"layer": "features", **rec}
        where = rec
        if not rec.get("line_code") and tracks is not None:
            loc_r, where = tracks, {**rec, "line_code": rec.get("track_id"), "track": ""}
        else:
            loc_r = loc
        geom = _span(loc_r, where, "_db_m") if rec.get("feature_id") is not None else _span(loc_r, where, "_m")
        out.append(feature(geom, props))
        if rec["status"] in ("moved", "new"):
            out.append(feature(_span(loc_r, where, "_m"), {**props, "layer": "feature_proposals"}))
    return out


def survey_geojson(network: Network, report: Any) -> dict[str, Any]:
    """``trainpos survey`` results (a :class:`fieldlogs.survey.result.SurveyReport`) over
    the DB's GIS grid: balises at their DB km with status (ok / moved / missed / unverified)
    and residual ± 95 % interval, candidates (status ``candidate``) at the runs' km, moved
    balises' DB → runs line, curves with their status and the runs' positions, and the GIS
    statistics like ``gis verify``'s. The wheel diameters are no place on the map: they are
    members of the FeatureCollection (``wheels``: ``vehicles``, ``runs``), beside ``db``,
    ``db_version``, ``summary``, ``gis_note`` and ``failed_runs`` (RFC 7946 §6.1 foreign
    members)."""
    loc = GridLocator(network)
    feats = _balise_features(loc, report.balises) + _candidate_features(loc, report.candidates)
    if len(report.features):
        off = report.features["line_code"].fillna("").astype(str) == ""
        feats += _curve_features(loc, report.features, GridLocator.along_tracks(network) if off.any() else None)
    if report.gis is not None:
        feats += _verification_features(loc, report.gis)
    if getattr(report, "gis_tracks", None) is not None:
        feats += _verification_features(GridLocator.along_tracks(network), report.gis_tracks, "pos")
    out = collection(feats, name="survey")
    out.update(
        jsonable(
            {
                "db": report.db,
                "db_version": report.db_version,
                "summary": report.summary(),
                "wheels": {"vehicles": _records(report.wheels), "runs": _records(report.wheel_runs)},
                "gis_note": report.gis_note,
                "failed_runs": _records(report.failed_runs),
            },
            9,
        )
    )
    return out
