"""Synthetic networks from alignment models: GIS grid, feature points, balises.

Used by the bundled sample network (an alignment fitted to a real line), by tests (small
hand-specified lines with known curves) and by benchmarks (national-scale networks).
Everything is derived from the :class:`~fieldlogs.simulate.networks.alignment.Alignment`, so the tables
are mutually consistent by construction; validation rules are tested by breaking them.

Track layout: trains keep left in Japan, so the down track (running in increasing km) lies
left of the centreline and the up track right of it.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from dbtools.gis.geometry import Projector
from dbtools.network import Network, canonical, empty_frame
from fieldlogs.simulate.networks.alignment import Alignment, Curve
from schemas.enums import Track
from schemas.tables import (
    BALISES,
    FEATURE_POINTS,
    FEATURE_TOLERANCE,
    GIS,
    GIS_SPACING_M,
    KM_BREAKS,
    LINES,
    PAIR_SPACING_M,
    TRACK_SPACING_M,
)

#: Lateral offset of each track from the line centreline [m], positive left of increasing km.
TRACK_OFFSETS: dict[str, float] = {Track.DOWN: TRACK_SPACING_M / 2, Track.UP: -TRACK_SPACING_M / 2, Track.SINGLE: 0.0}
#: Length of the straight checked before and after a curve [m] (SPEC §5.3: ≥ 20 m).
STRAIGHT_CHECK_M = 20.0
#: Distance of an initial pair's I1 before the station centre, in running direction [m].
PAIR_BEFORE_STATION_M = 250.0
#: Distance of the home signal's C balise before the station centre [m].
HOME_BEFORE_STATION_M = 450.0


@dataclass(frozen=True)
class Station:
    code: str
    name: str
    km_m: float


@dataclass
class LineSpec:
    """One line: alignment, stations, tracks and the realigned sections where the equipment
    km differs from the actual km (``(km_from, km_to, equipment − actual)``)."""

    line_code: str
    name: str
    alignment: Alignment
    stations: list[Station] = field(default_factory=list)
    tracks: tuple[str, ...] = (Track.DOWN, Track.UP)
    block_spacing_m: float = 1500.0
    equipment_shifts: list[tuple[float, float, float]] = field(default_factory=list)

    def offset(self, track: str) -> float:
        return TRACK_OFFSETS[track] if len(self.tracks) > 1 else 0.0

    def equipment_km(self, km: np.ndarray) -> np.ndarray:
        out = np.asarray(km, dtype=float).copy()
        for lo, hi, delta in self.equipment_shifts:
            out = np.where((km >= lo) & (km <= hi), out + delta, out)
        return out


def running_sign(track: str) -> int:
    return -1 if track == Track.UP else 1


def gis_grid(spec: LineSpec, projector: Projector) -> pd.DataFrame:
    """A point every 20 m of km on each track, lat/lon through the plane zone, rail height."""
    a = spec.alignment
    km = np.arange(np.ceil(a.km0 / GIS_SPACING_M), np.floor(a.km_end / GIS_SPACING_M) + 1) * GIS_SPACING_M
    s = a.chainage(km)
    frames = []
    for track in spec.tracks:
        x, y = a.xy(s, spec.offset(track))
        lon, lat = projector.to_lonlat(x, y)
        frames.append(
            pd.DataFrame(
                {
                    "line_code": spec.line_code,
                    "track": str(track),
                    "km_m": km,
                    "lat": np.round(lat, 9),
                    "lon": np.round(lon, 9),
                    "height_m": np.round(a.height(s), 3),
                }
            )
        )
    return pd.concat(frames, ignore_index=True)


def feature_rows(spec: LineSpec, curve: Curve, track: str, feature_id: str) -> list[dict[str, object]]:
    """The six rows of [S000 Table 1] for one curve on one track, in running order."""
    a = spec.alignment
    lower = 1.0 - FEATURE_TOLERANCE
    k = float(a.track_curvature(curve.sc_m + curve.arc_m / 2, spec.offset(track))[()])
    radius = round(1.0 / abs(k), 1)
    ts, st, lt = a.km(curve.start_m), a.km(curve.end_m), curve.transition_m
    sign = running_sign(track)
    left = curve.left if sign > 0 else not curve.left
    if sign > 0:
        kms = [ts - STRAIGHT_CHECK_M, ts, ts + lower * lt, st - lower * lt, st, st + STRAIGHT_CHECK_M]
    else:
        kms = [st + STRAIGHT_CHECK_M, st, st - lower * lt, ts + lower * lt, ts, ts - STRAIGHT_CHECK_M]
    rows = [
        ("straight", 0.0, "entry straight check starts"),
        ("transition", 0.0, "entry straight check ends"),
        ("left" if left else "right", radius, "curvature exceeds the lower limit (curve entry)"),
        ("transition", 0.0, "curvature falls below the lower limit (curve exit)"),
        ("straight", 0.0, "exit straight check starts"),
        ("none", 0.0, "exit straight check ends"),
    ]
    return [
        {
            "line_code": spec.line_code,
            "track": str(track),
            "feature_id": feature_id,
            "seq": i + 1,
            "km_m": round(float(km), 1),
            "radius_m": r,
            "attribute": attr,
            "role": role,
        }
        for i, (km, (attr, r, role)) in enumerate(zip(kms, rows, strict=True))
    ]


def feature_points(spec: LineSpec, min_straight_m: float = 2 * STRAIGHT_CHECK_M) -> pd.DataFrame:
    """Feature points for every curve with room for the straight checks on both sides."""
    a = spec.alignment
    rows: list[dict[str, object]] = []
    curves = a.curves
    for i, c in enumerate(curves):
        before = c.start_m - (curves[i - 1].end_m if i > 0 else 0.0)
        after = (curves[i + 1].start_m if i + 1 < len(curves) else a.length_m) - c.end_m
        if before < min_straight_m or after < min_straight_m:
            continue
        for track in spec.tracks:
            rows += feature_rows(spec, c, track, f"F{i + 1:03d}")
    return pd.DataFrame(rows) if rows else empty_frame(FEATURE_POINTS)


def balises(spec: LineSpec) -> pd.DataFrame:
    """Initial pairs at every station and track; C balises at home and block signals.

    Each C balise is governed by the last pair passed before it in running direction and
    carries the travel distance from that pair's I1.
    """
    rows: list[dict[str, object]] = []
    for track in spec.tracks:
        pair_rows, pairs = _pair_rows(spec, track)
        rows += pair_rows + _c_rows(spec, track, pairs)
    frame = pd.DataFrame(rows)
    if frame.empty:
        return empty_frame(BALISES)
    frame["km_actual_m"] = frame["km_actual_m"].round(2)
    frame["km_equipment_m"] = spec.equipment_km(frame["km_actual_m"].to_numpy()).round(2)
    frame["dist_from_initial_m"] = frame["dist_from_initial_m"].astype(float).round(2)
    return frame


def _pair_rows(spec: LineSpec, track: str) -> tuple[list[dict[str, object]], list[tuple[float, str]]]:
    """I1/I2 rows of every station's initial pair on one track, and the pairs (I1 km, station)."""
    a = spec.alignment
    sign = running_sign(track)
    rows: list[dict[str, object]] = []
    pairs: list[tuple[float, str]] = []
    for st in spec.stations:
        i1 = st.km_m - sign * PAIR_BEFORE_STATION_M
        i2 = i1 + sign * PAIR_SPACING_M
        if not (a.km0 <= min(i1, i2) and max(i1, i2) <= a.km_end):
            continue
        pairs.append((i1, st.code))
        for kind, km in (("I1", i1), ("I2", i2)):
            rows.append(
                {
                    "balise_id": f"{spec.line_code}-{st.code}-{track}-{kind}",
                    "kind": kind,
                    "line_code": spec.line_code,
                    "station_code": st.code,
                    "track": str(track),
                    "signal_type": None,
                    "km_actual_m": km,
                    "dist_from_initial_m": None,
                }
            )
    return rows, pairs


def _signal_kms(spec: LineSpec, sign: int) -> list[tuple[float, str]]:
    """(km, signal type) of the home signal of every station and the block signals between."""
    c_kms: list[tuple[float, str]] = [(st.km_m - sign * HOME_BEFORE_STATION_M, "home") for st in spec.stations]
    ordered = sorted(spec.stations, key=lambda s: s.km_m * sign)
    for s0, s1 in itertools.pairwise(ordered):
        span = abs(s1.km_m - s0.km_m)
        n_blocks = int(span // spec.block_spacing_m)
        for j in range(1, n_blocks):
            c_kms.append((s0.km_m + sign * j * span / n_blocks, "block"))
    return c_kms


def _c_rows(spec: LineSpec, track: str, pairs: list[tuple[float, str]]) -> list[dict[str, object]]:
    """C balises at the signals of one track, each governed by the last pair before it."""
    a = spec.alignment
    sign = running_sign(track)
    rows: list[dict[str, object]] = []
    for km, sig in sorted(_signal_kms(spec, sign), key=lambda t: t[0] * sign):
        governing = [(i1, code) for i1, code in pairs if (km - i1) * sign > PAIR_SPACING_M]
        if not governing or not (a.km0 <= km <= a.km_end):
            continue
        i1, code = max(governing, key=lambda p: p[0] * sign)
        rows.append(
            {
                "balise_id": f"{spec.line_code}-{track}-C{len(rows) + 1:03d}",
                "kind": "C",
                "line_code": spec.line_code,
                "station_code": code,
                "track": str(track),
                "signal_type": sig,
                "km_actual_m": km,
                "dist_from_initial_m": abs(km - i1),
            }
        )
    return rows


def build_network(specs: list[LineSpec], projector: Projector) -> Network:
    """A complete network (all content tables, canonical) from line specs, drawn in the
    plane of ``projector`` (any projected CRS: :meth:`Projector.from_epsg`), which the
    network declares as its metric CRS (meta ``metric_crs``)."""
    tables = {
        LINES.name: pd.DataFrame(
            {
                "line_code": [s.line_code for s in specs],
                "name": [s.name for s in specs],
                "attributes_json": [None] * len(specs),
            }
        ),
        GIS.name: pd.concat([gis_grid(s, projector) for s in specs], ignore_index=True),
        BALISES.name: pd.concat([balises(s) for s in specs], ignore_index=True),
        FEATURE_POINTS.name: pd.concat([feature_points(s) for s in specs], ignore_index=True),
        KM_BREAKS.name: empty_frame(KM_BREAKS),
    }
    net = Network(
        {t.name: canonical(t, tables[t.name]) for t in (LINES, GIS, BALISES, FEATURE_POINTS, KM_BREAKS)},
        origin="synthetic",
    )
    net.meta = {"metric_crs": f"EPSG:{projector.epsg}", "metric_crs_source": "declared"}
    return net


def random_alignment(
    rng: np.random.Generator,
    length_m: float,
    *,
    km0: float = 0.0,
    radius_m: tuple[float, float] = (300.0, 1500.0),
    straight_m: tuple[float, float] = (200.0, 1500.0),
    arc_m: tuple[float, float] = (80.0, 500.0),
    max_grade: float = 0.015,
    x0: float = 0.0,
    y0: float = 0.0,
    heading0: float | None = None,
) -> Alignment:
    """A plausible line: straights and curves with transitions, gentle gradients."""
    curves: list[Curve] = []
    s = float(rng.uniform(*straight_m))
    while True:
        r = float(rng.uniform(*radius_m))
        lt = float(np.clip(r * 0.12, 30.0, 100.0))
        la = float(rng.uniform(*arc_m))
        if s + 2 * lt + la + straight_m[0] > length_m:
            break
        curves.append(Curve(s, lt, la, r, bool(rng.integers(0, 2))))
        s = curves[-1].end_m + float(rng.uniform(*straight_m))
    knots = []
    g_s = 0.0
    while g_s < length_m:
        knots.append((g_s, float(rng.uniform(-max_grade, max_grade))))
        g_s += float(rng.uniform(800.0, 3000.0))
    # gradient changes spread over 200 m (vertical curves)
    grade_knots: list[tuple[float, float]] = []
    for i, (gs, gv) in enumerate(knots):
        if i > 0:
            grade_knots.append((gs, knots[i - 1][1]))
        grade_knots.append((gs + (200.0 if i > 0 else 0.0), gv))
    return Alignment(
        length_m,
        curves,
        x0=x0,
        y0=y0,
        heading0=float(rng.uniform(-np.pi, np.pi)) if heading0 is None else heading0,
        km0=km0,
        grade_knots=grade_knots,
    )


def demo_line(
    line_code: str = "0900", seed: int = 7, length_m: float = 12_000.0, *, x0: float = 0.0, y0: float = 0.0
) -> LineSpec:
    """A small double-track test line with stations every ~3 km (for tests and benchmarks),
    starting at plane (x0, y0) of whatever projection it is built in: the origin of a
    JGD2011 zone by default; e.g. ``x0=500_000, y0=5_000_000`` on a UTM central meridian."""
    rng = np.random.default_rng(seed)
    a = random_alignment(rng, length_m, km0=1000.0, x0=x0, y0=y0)
    stations = [
        Station(f"{i + 1:02d}", f"Station {i + 1}", a.km0 + 500.0 + i * 3000.0)
        for i in range(int((length_m - 1000.0) // 3000.0) + 1)
    ]
    return LineSpec(line_code, f"Test line {line_code}", a, stations)
