"""Generate the hand-made small networks of this folder (issue 30): ``python make_networks.py``.

Every network is drawn in a local metric frame (x east, y north, metres) and turned into
latitude/longitude by the azimuthal equidistant projection on GRS80 centred at
lat 60.2°, lon 24.9° (near Helsinki): within 1 km of the centre its scale error is below
10⁻⁸, so lengths and angles drawn in the frame are true on the ground. The source sets
declare ETRS-TM35FIN (EPSG:3067), Finland's metric CRS, in ``network.toml``.

Lines run east (km = x); a double-track line has its U track at y = +2 m and D at −2 m
(4.0 m apart). Turnouts are drawn as in the standard: the diverging branch leaves the
through track tangentially on a circular arc of the diverging radius R until it reaches the
frog angle α = atan(1/n), then runs straight. A crossover between two tracks d apart is arc R
(0 → α), straight, arc R (α → 0); its x-extent e is 2·R·sin α + s·cos α with the straight s
given by d = 2·R·(1 − cos α) + s·sin α, hence e = 2·R·tan(α/2) + d·cot α. Switch toes lie on
the 20 m km grid so that every track along a line ends on a grid point.

Tracks along a line have their centreline in ``gis`` (20 m km grid); crossovers and station
tracks in ``track_points`` (every 20 m of their own length plus the end, ``km_m`` the line km
of the point's projection on the line, x). Balise groups (kind G, NID_C 230) of two balises
3 m apart stand before the switches and just beyond each facing switch on each branch.

``tests/dbtools/test_networks_data.py`` checks that the committed files equal a fresh run.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

from pyproj import Proj

from fieldlogs.simulate.networks.turnout import Path2D, radius_for_extent, reverse_curves

HERE = Path(__file__).resolve().parent
LAT0, LON0 = 60.2, 24.9
_PROJ = Proj(proj="aeqd", lat_0=LAT0, lon_0=LON0, ellps="GRS80", units="m")
NID_C = 230
#: Half the distance between the U and D track centres [m].
HALF_SPACING = 2.0
STEP = 20.0

TRACK_COLS = ("track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m", "name")
CONN_COLS = ("track_a", "end_a", "track_b", "end_b", "navigability", "switch_id")
SWITCH_COLS = (
    "switch_id",
    "type",
    "a1_track",
    "a1_end",
    "b1_track",
    "b1_end",
    "b2_track",
    "b2_end",
    "a2_track",
    "a2_end",
    "diverging_side",
    "switch_number",
    "diverging_radius_m",
    "diverging_speed_kmh",
    "line_code",
    "km_m",
    "lat",
    "lon",
    "name",
)
BALISE_COLS = (
    "balise_id",
    "kind",
    "line_code",
    "station_code",
    "track",
    "signal_type",
    "km_actual_m",
    "km_equipment_m",
    "dist_from_initial_m",
    "track_id",
    "nid_c",
    "nid_bg",
    "n_pig",
    "n_total",
    "link_group",
    "link_distance_m",
)


def latlon(x: float, y: float) -> tuple[float, float]:
    lon, lat = _PROJ(x, y, inverse=True)
    return float(lat), float(lon)


def crossover_path(x0: float, y0: float, d: float, n: float, radius: float, *, left: bool) -> Path2D:
    """Arc R (0 → α), straight, arc R (α → 0) joining two parallel eastward tracks d apart."""
    return reverse_curves(x0, y0, d, n, radius, 1.0 if left else -1.0)


def f(v: float | int | str | None, digits: int = 3) -> str:
    if v is None:
        return ""
    if isinstance(v, str):
        return v
    if isinstance(v, int):
        return str(v)
    text = f"{v:.{digits}f}".rstrip("0").rstrip(".")
    return "0" if text == "-0" else text


@dataclass
class Net:
    gis: list[tuple[str, str, float, float, float]] = field(default_factory=list)
    tracks: list[dict[str, object]] = field(default_factory=list)
    conns: list[dict[str, object]] = field(default_factory=list)
    switches: list[dict[str, object]] = field(default_factory=list)
    points: list[tuple[str, float, float, float, float]] = field(default_factory=list)
    balises: list[dict[str, object]] = field(default_factory=list)
    paths: dict[str, Path2D] = field(default_factory=dict)
    """Line/track key 'LINE/TRACK' or track id → its drawn path, for placing points."""
    next_bg: int = 1

    def line(self, line: str, track: str, path: Path2D, km0: float = 0.0) -> None:
        """The 20 m gis grid of a line track drawn as ``path`` (km = km0 + arc length)."""
        self.paths[f"{line}/{track}"] = path
        k = 0.0
        while k <= path.length + 1e-9:
            x, y, _ = path.at(k)
            self.gis.append((line, track, km0 + k, *latlon(x, y)))
            k += STEP

    def track(
        self, tid: str, line: str | None, track: str | None, kind: str, k0: float, k1: float, **kw: object
    ) -> None:
        length = kw.pop("length") if "length" in kw else abs(k1 - k0)
        self.tracks.append(
            {"track_id": tid, "line_code": line, "track": track, "kind": kind, "km_begin_m": k0, "km_end_m": k1}
            | {"length_m": length, "name": kw.pop("name", None)}
        )

    def own_track(self, tid: str, line: str | None, track: str | None, kind: str, path: Path2D) -> None:
        """A track with its centreline in track_points (every 20 m and the end), km = x."""
        self.paths[tid] = path
        length = path.length
        pos = [i * STEP for i in range(int(length // STEP) + 1)]
        if length - pos[-1] < 1.0:
            pos.pop()  # the end stands for a grid point less than 1 m before it
        pos.append(length)
        for p in pos:
            x, y, _ = path.at(p)
            self.points.append((tid, p, x, *latlon(x, y)))
        k0, k1 = (path.at(0)[0], path.at(length)[0]) if line else (None, None)
        self.track(tid, line, track, kind, k0, k1, length=length)  # type: ignore[arg-type]

    def connect(self, ta: str, ea: str, tb: str, eb: str, nav: str = "both", switch: str | None = None) -> None:
        self.conns.append(
            {"track_a": ta, "end_a": ea, "track_b": tb, "end_b": eb, "navigability": nav, "switch_id": switch}
        )

    def point_switch(
        self, sid: str, toe: tuple[str, str], left: tuple[str, str], right: tuple[str, str], **kw: object
    ) -> None:
        """A point switch: ports, the three connections (toe↔branches both, branch↔branch none)."""
        self.switches.append(
            {"switch_id": sid, "type": "point", "a1_track": toe[0], "a1_end": toe[1]}
            | {"b1_track": left[0], "b1_end": left[1], "b2_track": right[0], "b2_end": right[1]}
            | kw
        )
        self.connect(*toe, *left, "both", sid)
        self.connect(*toe, *right, "both", sid)
        self.connect(*left, *right, "none", sid)

    def group(self, track_id: str, line: str | None, track: str | None, km: float, *, size: int = 2) -> None:
        """A balise group of ``size`` balises 3 m apart from km on (nominal direction: km increasing)."""
        bg = self.next_bg
        self.next_bg += 1
        for i in range(size):
            self.balises.append(
                {"balise_id": f"BG{bg}.{i}", "kind": "G", "line_code": line, "track": track}
                | {"km_actual_m": km + 3.0 * i, "km_equipment_m": km + 3.0 * i, "track_id": track_id}
                | {"nid_c": NID_C, "nid_bg": bg, "n_pig": i, "n_total": size}
            )

    def files(self) -> dict[str, str]:
        gis = ["line_code,track,km_m,lat,lon"] + [
            f"{lc},{tr},{f(k)},{f(la, 9)},{f(lo, 9)}" for lc, tr, k, la, lo in self.gis
        ]
        pts = ["track_id,pos_m,km_m,lat,lon"] + [
            f"{t},{f(p)},{f(k)},{f(la, 9)},{f(lo, 9)}" for t, p, k, la, lo in self.points
        ]
        out = {
            "network.toml": 'metric_crs = "EPSG:3067"\n',
            "gis.csv": "\n".join(gis) + "\n",
            "feature_points.csv": "line_code,track,feature_id,km_m,radius_m,attribute,role\n",
            "balises.csv": _csv(BALISE_COLS, self.balises),
            "tracks.csv": _csv(TRACK_COLS, self.tracks),
            "connections.csv": _csv(CONN_COLS, self.conns),
            "switches.csv": _csv(SWITCH_COLS, self.switches),
        }
        if self.points:
            out["track_points.csv"] = "\n".join(pts) + "\n"
        return out


def _csv(cols: tuple[str, ...], rows: list[dict[str, object]]) -> str:
    def cell(v: object) -> str:
        return f(v, 9)  # type: ignore[arg-type]

    lines = [",".join(cols)] + [",".join(cell(r.get(c)) for c in cols) for r in rows]
    return "\n".join(lines) + "\n"


def _switch_at(
    line: str, km: float, x: float, y: float, n: float, radius: float, side: str, **kw: object
) -> dict[str, object]:
    lat, lon = latlon(x, y)
    return (
        {"switch_number": n, "diverging_radius_m": radius, "diverging_side": side, "line_code": line}
        | {
            "km_m": km,
            "lat": round(lat, 9),
            "lon": round(lon, 9),
        }
        | kw
    )


def junction() -> Net:
    """Main line 9001 (S, km 0–1000 east) splits at km 400 (switch W1, 1:9, R 190 m) into its
    through track and line 9002 (S, own km 0 at the toe) diverging left: arc R 190 m to the
    frog angle, 40 m straight, arc R 500 m to 30°, straight to km 600."""
    n = Net()
    a9 = math.atan(1 / 9)
    n.line("9001", "S", Path2D(0, 0).straight(1000))
    branch = Path2D(400, 0).arc(190, a9).straight(40).arc(500, math.radians(30) - a9)
    branch.straight(600 - branch.length)
    n.line("9002", "S", branch)
    n.track("A1", "9001", "S", "main", 0, 400)
    n.track("A2", "9001", "S", "main", 400, 1000)
    n.track("B1", "9002", "S", "main", 0, 600)
    n.point_switch(
        "W1", ("A1", "end"), ("B1", "begin"), ("A2", "begin"), **_switch_at("9001", 400, 400, 0, 9, 190, "left")
    )
    n.group("A1", "9001", "S", 300)
    n.group("A2", "9001", "S", 440)  # just beyond the facing switch, through branch
    n.group("B1", "9002", "S", 40)  # … diverging branch
    n.group("A2", "9001", "S", 800)
    n.group("B1", "9002", "S", 400)
    return n


def _double_track(n: Net, line: str) -> None:
    n.line(line, "D", Path2D(0, -HALF_SPACING).straight(1000))
    n.line(line, "U", Path2D(0, HALF_SPACING).straight(1000))


def crossover() -> Net:
    """Double-track line 9003 (U at y = +2 m, D at −2 m, km 0–1000) with a crossover pair of
    1:10 turnouts, each crossover 60 m long in x (R from :func:`radius_for_extent`, ≈ 200.5 m):
    X1 from D km 300 (W1, toe west) up to U km 360 (W2, toe east), X2 from U km 600 (W3, toe
    west) down to D km 660 (W4, toe east)."""
    n = Net()
    line, d, num = "9003", 2 * HALF_SPACING, 10.0
    radius = radius_for_extent(60.0, d, num)
    _double_track(n, line)
    for tid, tr, k0, k1 in (
        ("D1", "D", 0, 300),
        ("D2", "D", 300, 660),
        ("D3", "D", 660, 1000),
        ("U1", "U", 0, 360),
        ("U2", "U", 360, 600),
        ("U3", "U", 600, 1000),
    ):
        n.track(tid, line, tr, "main", k0, k1)
    n.own_track("X1", None, None, "crossover", crossover_path(300, -HALF_SPACING, d, num, radius, left=True))
    n.own_track("X2", None, None, "crossover", crossover_path(600, HALF_SPACING, d, num, radius, left=False))
    r = round(radius, 1)
    n.point_switch(
        "W1", ("D1", "end"), ("X1", "begin"), ("D2", "begin"), **_switch_at(line, 300, 300, -2, num, r, "left")
    )
    n.point_switch("W2", ("U2", "begin"), ("X1", "end"), ("U1", "end"), **_switch_at(line, 360, 360, 2, num, r, "left"))
    n.point_switch(
        "W3", ("U2", "end"), ("U3", "begin"), ("X2", "begin"), **_switch_at(line, 600, 600, 2, num, r, "right")
    )
    n.point_switch(
        "W4", ("D3", "begin"), ("D2", "end"), ("X2", "end"), **_switch_at(line, 660, 660, -2, num, r, "right")
    )
    n.group("D1", line, "D", 200)
    n.group("D2", line, "D", 320)  # beyond facing W1 (D runs km increasing): through branch
    n.group("X1", line, None, 328)  # … diverging branch, on the crossover
    n.group("U3", line, "U", 700)
    n.group("U2", line, "U", 560)  # beyond facing W2 (U runs km decreasing): through branch
    n.group("D2", line, "D", 480)
    return n


def station4() -> Net:
    """Double-track line 9004 (km 0–1000) through a station of four tracks: station track 3
    north of U and 4 south of D (4.5 m out), each leaving its main track at km 200 and
    rejoining it at km 800 by 1:9 R 190 m turnouts (arc, straight, reverse arc). Tracks 3 and
    4 lie along the line (line_code 9004, km 200–800) with their centreline in track_points."""
    n = Net()
    line, num, radius, out = "9004", 9.0, 190.0, 4.5
    _double_track(n, line)
    a = math.atan(1 / num)
    s = (out - 2 * radius * (1 - math.cos(a))) / math.sin(a)
    ext = 2 * radius * math.sin(a) + s * math.cos(a)
    for tid, y, sign in (("3", HALF_SPACING, 1.0), ("4", -HALF_SPACING, -1.0)):
        p = Path2D(200, y).arc(radius, sign * a).straight(s).arc(radius, -sign * a).straight(600 - 2 * ext)
        p.arc(radius, -sign * a).straight(s).arc(radius, sign * a)
        n.own_track(tid, line, tid, "station", p)
    for tid, tr, k0, k1 in (
        ("U1", "U", 0, 200),
        ("U2", "U", 200, 800),
        ("U3", "U", 800, 1000),
        ("D1", "D", 0, 200),
        ("D2", "D", 200, 800),
        ("D3", "D", 800, 1000),
    ):
        n.track(tid, line, tr, "main", k0, k1)
    y = HALF_SPACING
    n.point_switch(
        "W1", ("U1", "end"), ("3", "begin"), ("U2", "begin"), **_switch_at(line, 200, 200, y, num, radius, "left")
    )
    n.point_switch(
        "W2", ("U3", "begin"), ("U2", "end"), ("3", "end"), **_switch_at(line, 800, 800, y, num, radius, "right")
    )
    n.point_switch(
        "W3", ("D1", "end"), ("D2", "begin"), ("4", "begin"), **_switch_at(line, 200, 200, -y, num, radius, "right")
    )
    n.point_switch(
        "W4", ("D3", "begin"), ("4", "end"), ("D2", "end"), **_switch_at(line, 800, 800, -y, num, radius, "left")
    )
    n.group("D1", line, "D", 100)
    n.group("D2", line, "D", 240)  # beyond facing W3 (D: km increasing)
    n.group("4", line, None, 240)
    n.group("U3", line, "U", 900)
    n.group("U2", line, "U", 757)  # beyond facing W2 (U: km decreasing)
    n.group("3", line, None, 757)
    return n


def double_slip() -> Net:
    """Line 9005 (S, km 0–1000 east) crossed at its km 500 by line 9006 (S, straight at the
    angle atan(1/9) north of east, its km 500 at the crossing) with a double slip D1:
    A1 = 9005 west part, B1 = 9005 east part, A2 = 9006 south-west part, B2 = 9006 north-east
    part; routes A1–B1, A2–B2 and the slips A1–B2, A2–B1; A1–A2 and B1–B2 are not navigable."""
    n = Net()
    a = math.atan(1 / 9)
    n.line("9005", "S", Path2D(0, 0).straight(1000))
    n.line("9006", "S", Path2D(500 - 500 * math.cos(a), -500 * math.sin(a), a).straight(1000))
    for tid, line, k0, k1 in (
        ("P1", "9005", 0, 500),
        ("P2", "9005", 500, 1000),
        ("Q1", "9006", 0, 500),
        ("Q2", "9006", 500, 1000),
    ):
        n.track(tid, line, "S", "main", k0, k1)
    lat, lon = latlon(500, 0)
    n.switches.append(
        {"switch_id": "DS1", "type": "double_slip", "a1_track": "P1", "a1_end": "end", "b1_track": "P2"}
        | {"b1_end": "begin", "b2_track": "Q2", "b2_end": "begin", "a2_track": "Q1", "a2_end": "end"}
        | {"switch_number": 9.0, "diverging_radius_m": 190.0, "line_code": "9005", "km_m": 500.0}
        | {"lat": round(lat, 9), "lon": round(lon, 9)}
    )
    for ta, tb, nav in (("P1", "P2", "both"), ("Q1", "Q2", "both"), ("P1", "Q2", "both"), ("Q1", "P2", "both")):
        n.connect(ta, "end", tb, "begin", nav, "DS1")
    n.connect("P1", "end", "Q1", "end", "none", "DS1")
    n.connect("P2", "begin", "Q2", "begin", "none", "DS1")
    n.group("P1", "9005", "S", 400)
    n.group("Q1", "9006", "S", 400)
    n.group("P2", "9005", "S", 540)  # beyond the slip, facing from A1 or A2
    n.group("Q2", "9006", "S", 540)
    return n


NETWORKS = {"junction": junction, "crossover": crossover, "station4": station4, "double_slip": double_slip}


def generate() -> dict[str, dict[str, str]]:
    """Network name → file name → text."""
    return {name: build().files() for name, build in NETWORKS.items()}


def main(out: Path = HERE) -> None:
    for name, files in generate().items():
        (out / name).mkdir(parents=True, exist_ok=True)
        for fname, text in files.items():
            (out / name / fname).write_text(text, encoding="utf-8", newline="\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE)
