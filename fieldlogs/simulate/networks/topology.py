"""Station layouts on synthetic double-track lines: the network tables of a national-scale
benchmark network (``bench/bench_db.py``) and of tests.

At every station of a :class:`~fieldlogs.simulate.networks.synthetic.LineSpec` with tracks D and U, a
loop track beside each main track (station tracks ``3`` beside D, ``4`` beside U, from 120 m
before to 120 m after the station centre) and one crossover D → U just after the loops; the
main tracks are split into tracks at every switch. Geometry comes from the alignment itself
(:meth:`Alignment.xy` at a lateral offset), so the tables are consistent by construction:

* a loop leaves its main track at a 1:``LOOP_N`` switch, reaches ``LOOP_OFFSET_M`` beside it
  after ``LEAD_M`` on the turnout's reverse curve (:mod:`fieldlogs.simulate.networks.turnout`: arc of the
  diverging radius to the frog angle atan(1/n), straight, arc back) and comes back the same way;
* the crossover goes from D to U over ``LEAD_M`` on the reverse curve of two 1:``CROSSOVER_N``
  turnouts. The switches carry their switch number and diverging radius.

Switch ends are on the 20 m km grid, so a main track's pieces meet at grid points and each
piece's centreline is its line grid between its end km.
"""

from __future__ import annotations

import itertools
from typing import Any, cast

import numpy as np
import pandas as pd

from dbtools.gis.geometry import Projector
from fieldlogs.simulate.networks.synthetic import LineSpec
from fieldlogs.simulate.networks.turnout import radius_for_extent, reverse_curve_offset
from schemas.enums import BaliseKind, Navigability, Side, SwitchType, Track, TrackKind
from schemas.tables import GIS_SPACING_M

#: Lateral distance of a loop track from its main track [m].
LOOP_OFFSET_M = 4.5
#: Length over which a turnout or crossover reaches its full offset [m] (on the 20 m grid).
LEAD_M = 60.0
#: Switch numbers of the loop turnouts (R ≈ 193 m over LEAD_M) and of the crossovers (R ≈ 220 m).
LOOP_N, CROSSOVER_N = 8.0, 10.0
#: Half length of a loop, from the station centre to each of its switches [m].
LOOP_HALF_M = 120.0

_BOTH, _NONE = Navigability.BOTH.value, Navigability.NONE.value


def _grid(km: float) -> float:
    return float(round(km / GIS_SPACING_M) * GIS_SPACING_M)


def _points(spec: LineSpec, projector: Projector, km: np.ndarray, offset: np.ndarray) -> tuple[np.ndarray, ...]:
    a = spec.alignment
    s = a.chainage(km)
    x, y = a.xy(s)
    h = a.heading(s)
    x, y = x - offset * np.sin(h), y + offset * np.cos(h)  # as Alignment.xy, offset per point
    lon, lat = projector.to_lonlat(x, y)
    return np.round(lat, 9), np.round(lon, 9)


class _Layout:
    """The rows of one line's network tables, accumulated station by station."""

    def __init__(self, spec: LineSpec, projector: Projector) -> None:
        self.spec, self.projector = spec, projector
        self.tracks: list[dict[str, object]] = []
        self.connections: list[dict[str, object]] = []
        self.switches: list[dict[str, object]] = []
        self.points: list[pd.DataFrame] = []
        self.balises: list[dict[str, object]] = []
        self.splits: dict[str, list[float]] = {Track.DOWN: [], Track.UP: []}

    def main_id(self, track: str, i: int) -> str:
        return f"{self.spec.line_code}-{track}-{i}"

    def side_track(self, tid: str, name: str, kind: str, km: np.ndarray, offset: np.ndarray) -> None:
        """A loop or crossover: track row and its track_points (pos along its polyline)."""
        lat, lon = _points(self.spec, self.projector, km, offset)
        x, y = self.projector.to_xy(lon, lat)
        pos = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
        self.points.append(
            pd.DataFrame({"track_id": tid, "pos_m": np.round(pos, 3), "km_m": km, "lat": lat, "lon": lon})
        )
        self.tracks.append(
            {
                "track_id": tid,
                "line_code": self.spec.line_code,
                "track": name,
                "kind": kind,
                "km_begin_m": float(km[0]),
                "km_end_m": float(km[-1]),
                "length_m": round(float(pos[-1]), 3),
            }
        )

    def switch(
        self, sid: str, main: str, km: float, branch: tuple[str, str], side: str, n: float, radius: float
    ) -> None:
        """A point switch on main track ``main`` at ``km`` whose diverging branch is the given
        track end; the toe is the main piece on the far side from the branch (placeholder
        track ids ``<main>@<km>@lo|hi`` are resolved once the main tracks are split)."""
        self.splits[main].append(km)
        diverges_up = branch[1] == "begin"  # the branch leaves towards increasing km
        toe = (main, km, "lo") if diverges_up else (main, km, "hi")
        through = (main, km, "hi") if diverges_up else (main, km, "lo")
        left, right = (branch, through) if side == Side.LEFT.value else (through, branch)
        lat, lon = _points(self.spec, self.projector, np.array([km]), np.array([self.spec.offset(main)]))
        self.switches.append(
            {
                "switch_id": sid,
                "type": SwitchType.POINT.value,
                "a1": toe,
                "b1": left,
                "b2": right,
                "diverging_side": side,
                "switch_number": n,
                "diverging_radius_m": round(radius, 1),
                "line_code": self.spec.line_code,
                "km_m": km,
                "lat": float(lat[0]),
                "lon": float(lon[0]),
            }
        )


def _station(lay: _Layout, code: str, centre: float) -> None:
    spec, d_off, u_off = lay.spec, lay.spec.offset(Track.DOWN), lay.spec.offset(Track.UP)
    k1, k2 = _grid(centre - LOOP_HALF_M), _grid(centre + LOOP_HALF_M)
    for main, name, off, sign in ((Track.DOWN, "3", d_off, 1.0), (Track.UP, "4", u_off, -1.0)):
        km = np.arange(k1, k2 + GIS_SPACING_M / 2, GIS_SPACING_M)
        out = reverse_curve_offset(np.minimum(km - k1, k2 - km), LEAD_M, LOOP_OFFSET_M, LOOP_N)
        tid = f"{spec.line_code}-{code}-{name}"
        ident = (int(spec.line_code) * 100 + int(code)) * 2 + (0 if sign > 0 else 1)  # a group per loop
        lay.side_track(tid, name, TrackKind.STATION.value, km, off + sign * out)
        # D's loop lies left of increasing km, U's right of it; seen from the toe at k2 the sides swap
        near, far = (Side.LEFT.value, Side.RIGHT.value) if sign > 0 else (Side.RIGHT.value, Side.LEFT.value)
        r_loop = radius_for_extent(LEAD_M, LOOP_OFFSET_M, LOOP_N)
        lay.switch(f"{tid}-W1", main, k1, (tid, "begin"), near, LOOP_N, r_loop)
        lay.switch(f"{tid}-W2", main, k2, (tid, "end"), far, LOOP_N, r_loop)
        for n_pig in range(2):
            lay.balises.append(
                {
                    "balise_id": f"{tid}-BG{n_pig}",
                    "kind": BaliseKind.G.value,
                    "line_code": spec.line_code,
                    "track": name,
                    "km_actual_m": centre + 3.0 * n_pig,
                    "km_equipment_m": centre + 3.0 * n_pig,
                    "track_id": tid,
                    "nid_c": 1 + ident // 16384,
                    "nid_bg": ident % 16384,
                    "n_pig": n_pig,
                    "n_total": 2,
                }
            )
    kc = k2 + GIS_SPACING_M * 2
    km = np.arange(kc, kc + LEAD_M + GIS_SPACING_M / 2, GIS_SPACING_M)
    tid = f"{spec.line_code}-{code}-X"
    spacing = abs(u_off - d_off)
    shift = np.sign(u_off - d_off) * reverse_curve_offset(km - kc, LEAD_M, spacing, CROSSOVER_N)
    lay.side_track(tid, f"X{code}", TrackKind.CROSSOVER.value, km, d_off + shift)
    r_x = radius_for_extent(LEAD_M, spacing, CROSSOVER_N)
    lay.switch(f"{tid}-W1", Track.DOWN, kc, (tid, "begin"), Side.RIGHT.value, CROSSOVER_N, r_x)
    lay.switch(f"{tid}-W2", Track.UP, kc + LEAD_M, (tid, "end"), Side.RIGHT.value, CROSSOVER_N, r_x)


def _split_mains(lay: _Layout) -> dict[tuple[str, float, str], tuple[str, str]]:
    """Main track pieces between switches; ``(main, km, lo|hi)`` → (piece, end) at that km."""
    spec, ends = lay.spec, {}
    a = spec.alignment
    lo_km, hi_km = _grid(np.ceil(a.km0 / GIS_SPACING_M) * GIS_SPACING_M), _grid(a.km_end - GIS_SPACING_M / 2)
    for main, splits in lay.splits.items():
        cuts = [lo_km, *sorted(set(splits)), hi_km]
        for i, (k0, k1) in enumerate(itertools.pairwise(cuts)):
            tid = lay.main_id(main, i)
            lay.tracks.append(
                {
                    "track_id": tid,
                    "line_code": spec.line_code,
                    "track": str(main),
                    "kind": TrackKind.MAIN.value,
                    "km_begin_m": k0,
                    "km_end_m": k1,
                    "length_m": k1 - k0,
                }
            )
            ends[(main, k0, "hi")] = (tid, "begin")
            ends[(main, k1, "lo")] = (tid, "end")
    return ends


def _resolve(lay: _Layout, ends: dict[tuple[str, float, str], tuple[str, str]]) -> None:
    """Ports from placeholders to track ends; the switch's connections."""
    for s in lay.switches:
        for port in ("a1", "b1", "b2"):
            ref = cast(tuple[Any, ...], s.pop(port))
            track, end = ends[cast(tuple[str, float, str], ref)] if len(ref) == 3 else ref
            s[f"{port}_track"], s[f"{port}_end"] = track, end
        toe = (s["a1_track"], s["a1_end"])
        for (ta, ea), (tb, eb), nav in (
            (toe, (s["b1_track"], s["b1_end"]), _BOTH),
            (toe, (s["b2_track"], s["b2_end"]), _BOTH),
            ((s["b1_track"], s["b1_end"]), (s["b2_track"], s["b2_end"]), _NONE),
        ):
            lay.connections.append(
                {
                    "track_a": ta,
                    "end_a": ea,
                    "track_b": tb,
                    "end_b": eb,
                    "navigability": nav,
                    "switch_id": s["switch_id"],
                }
            )


def station_network(spec: LineSpec, projector: Projector) -> dict[str, pd.DataFrame]:
    """The network tables (tracks, connections, switches, track_points) and the G balises of
    one double-track line with a loop pair and a crossover at each of its stations."""
    lay = _Layout(spec, projector)
    for st in spec.stations:
        _station(lay, st.code, st.km_m)
    _resolve(lay, _split_mains(lay))
    return {
        "tracks": pd.DataFrame(lay.tracks),
        "connections": pd.DataFrame(lay.connections),
        "switches": pd.DataFrame(lay.switches),
        "track_points": pd.concat(lay.points, ignore_index=True) if lay.points else pd.DataFrame(),
        "balises": pd.DataFrame(lay.balises),
    }
