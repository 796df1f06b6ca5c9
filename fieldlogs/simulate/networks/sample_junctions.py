"""The network part of the bundled sample: a four-track station, a crossover pair and a
junction on the straight between Matoba (km 21k061) and the curve at km 22k703, west of
the stretch the road-rail sample works in (km 22k032–22k632: its off-rail GPS fixes 8 m
left of D must not lie near the branch).

Drawn on the sample's own double track (the ``gis`` grid: D 1.9 m left of the centreline in
increasing km, U 1.9 m right), in a local frame (a along D from its km 20k800 point, l to the
left), and turned back into latitude/longitude with the grid's projection:

* **station** (Matoba, four tracks): loop ``3`` beside D (left) and loop ``4`` beside U
  (right), 4.5 m out, leaving their main track at km 20k800 and rejoining it at km 21k320 by
  1:10 turnouts of R = 200 m: arc R (0 → α), straight, arc R (α → 0), with α = atan(1/n) the
  frog angle; the straight s reaches the offset d: d = 2·R·(1 − cos α) + s·sin α;
* **crossover pair**: X1 from D km 21k400 to U km 21k460 and X2 from U km 21k540 to D km
  21k600, 1:10 turnouts whose radius gives the 60 m extent e = 2·R·tan(α/2) + d·cot α between
  toes on the 20 m grid (d = 3.8 m: R ≈ 220.5 m);
* **junction**: the single-track branch line ``0421`` leaves D at km 21k700 to the left by a
  1:12 turnout of R = 300 m, then 40 m straight, a R = 500 m curve to 30° and straight, 1.5 km
  of its own km (its ``gis`` grid, every 20 m).

Every arc of these paths with straights of at least ``MIN_STRAIGHT`` on both sides on its own
track is a curve feature point of ``track_feature_points`` (:func:`path_features`): the inner
reverse curves of the loops and the branch's R = 500 m curve. The turnout arcs at the toes
(no straight before them on the track) and the crossovers' arcs (16 m apart) are not.

The main tracks are split at every switch toe (all on the 20 m grid). ETCS-style balise
groups (kind G, two balises 3 m apart) stand just beyond each facing switch on each branch
and on each loop (S003 §4.3: after a junction the next group names the track); NID_C 800
is an invented region code. No new S003 balise: the existing runs' telegrams stay the same.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.gis.georef import projector_for_points
from fieldlogs.simulate.networks.turnout import Path2D, radius_for_extent, reverse_curves
from schemas.enums import Attribute, BaliseKind, Navigability, Side, SwitchType, TrackKind
from schemas.model import Table

LINE = "0420"
BRANCH = "0421"
BRANCH_NAME = "Kawagoe Line branch (sample, invented)"
NID_C = 800
#: Where the local frame starts on D, and how far the straight it draws on reaches [km m].
KM0, KM_STRAIGHT_END = 20_800.0, 22_700.0
TRACK_SPACING = 3.8
LOOP_OUT = 4.5
STEP = 20.0
TOES = {"loop_lo": 20_800.0, "loop_hi": 21_320.0, "x1": 21_400.0, "x2": 21_540.0, "junction": 21_700.0}
X_EXTENT = 60.0


#: A drawn arc is a feature point where straights of at least this length lie on both sides of
#: it on its own track [m] (the S000 straight checks: ``validate.min_straight_m``).
MIN_STRAIGHT = 20.0
#: Rows 1 and 6 (where the straight checks start and end) at most this far from the curve [m].
STRAIGHT_CHECK = 40.0


def path_features(tid: str, path: Path2D) -> list[dict[str, object]]:
    """``track_feature_points`` rows of the arcs of ``path`` (track ``tid``, pos = arc length
    along the path) with straights of at least ``MIN_STRAIGHT`` on both sides: six rows each
    [S000 Table 1], no transitions (rows 2–3 and 4–5 coincide), left/right as seen begin → end."""
    rows: list[dict[str, object]] = []
    at, n = 0.0, 0
    pc = path.pieces
    for j, (length, k) in enumerate(pc):
        inner = 0 < j < len(pc) - 1 and k != 0.0 and pc[j - 1][1] == 0.0 and pc[j + 1][1] == 0.0
        if inner and min(pc[j - 1][0], pc[j + 1][0]) >= MIN_STRAIGHT:
            n += 1
            a0, a1 = at, at + length
            before, after = min(pc[j - 1][0], STRAIGHT_CHECK), min(pc[j + 1][0], STRAIGHT_CHECK)
            side = Attribute.LEFT.value if k > 0 else Attribute.RIGHT.value
            spec = (
                (a0 - before, 0.0, Attribute.STRAIGHT.value, "entry straight check starts"),
                (a0, 0.0, Attribute.TRANSITION.value, "entry straight check ends"),
                (a0, round(1.0 / abs(k), 1), side, "curve entry"),
                (a1, 0.0, Attribute.TRANSITION.value, "curve exit"),
                (a1, 0.0, Attribute.STRAIGHT.value, "exit straight check starts"),
                (a1 + after, 0.0, Attribute.NONE.value, "exit straight check ends"),
            )
            for seq, (pos, radius, attr, role) in enumerate(spec, start=1):
                rows.append(
                    {"track_id": tid, "feature_id": f"F{n}", "seq": seq, "pos_m": round(pos, 3)}
                    | {"radius_m": radius, "attribute": attr, "role": role}
                )
        at += length
    return rows


def extent(p: Path2D) -> float:
    return p.at(p.length)[0] - p.x0


class _Frame:
    """The local frame on the sample's straight D track: (a, l) ↔ lat/lon, height by km."""

    def __init__(self, gis: pd.DataFrame) -> None:
        d = gis[(gis["line_code"] == LINE) & (gis["track"] == "D")].sort_values("km_m")
        self.km, self.h = d["km_m"].to_numpy(float), d["height_m"].to_numpy(float)
        self.proj = projector_for_points(d["lat"].to_numpy(float), d["lon"].to_numpy(float))
        x, y = self.proj.to_xy(d["lon"].to_numpy(float), d["lat"].to_numpy(float))
        i0, i1 = np.searchsorted(self.km, [KM0, KM_STRAIGHT_END])
        self.x0, self.y0 = float(x[i0]), float(y[i0])
        dx, dy = float(x[i1] - x[i0]), float(y[i1] - y[i0])
        norm = math.hypot(dx, dy)
        self.t = (dx / norm, dy / norm)
        self.scale = norm / (self.km[i1] - self.km[i0])  # plane metres per km metre (≈ 1)

    def latlon(self, a: np.ndarray, lat_off: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        tx, ty = self.t
        x = self.x0 + self.scale * a * tx - lat_off * ty
        y = self.y0 + self.scale * a * ty + lat_off * tx
        lon, lat = self.proj.to_lonlat(x, y)
        return np.round(lat, 9), np.round(lon, 9)

    def height(self, km: np.ndarray) -> np.ndarray:
        return np.asarray(np.round(np.interp(km, self.km, self.h), 3))


class _Tables:
    def __init__(self, frame: _Frame) -> None:
        self.f = frame
        self.tracks: list[dict[str, object]] = []
        self.conns: list[dict[str, object]] = []
        self.switches: list[dict[str, object]] = []
        self.points: list[pd.DataFrame] = []
        self.balises: list[dict[str, object]] = []
        self.gis: list[pd.DataFrame] = []
        self.features: list[dict[str, object]] = []

    def main(self, tid: str, track: str, k0: float, k1: float) -> None:
        self.tracks.append(
            {"track_id": tid, "line_code": LINE, "track": track, "kind": TrackKind.MAIN.value}
            | {"km_begin_m": k0, "km_end_m": k1, "length_m": k1 - k0, "name": None}
        )

    def own(self, tid: str, track: str | None, kind: str, path: Path2D, name: str) -> None:
        """A track with its centreline in track_points: every 20 m and its end, km = a."""
        length = path.length
        pos = list(np.arange(0.0, length, STEP))
        if length - pos[-1] < 1.0:
            pos.pop()
        pos.append(length)
        al = np.array([path.at(p)[:2] for p in pos])
        km = KM0 + al[:, 0]
        lat, lon = self.f.latlon(al[:, 0], al[:, 1])
        self.points.append(
            pd.DataFrame(
                {"track_id": tid, "pos_m": np.round(pos, 3), "km_m": np.round(km, 3), "lat": lat, "lon": lon}
                | {"height_m": self.f.height(km)}
            )
        )
        self.features += path_features(tid, path)
        line = LINE if track else None
        row: dict[str, object] = {"track_id": tid, "line_code": line, "track": track, "kind": kind}
        self.tracks.append(
            row
            | {
                "km_begin_m": float(round(km[0], 3)) if line else None,
                "km_end_m": float(round(km[-1], 3)) if line else None,
            }
            | {"length_m": round(length, 3), "name": None}
        )

    def switch(
        self, sid: str, toe: tuple[str, str], left: tuple[str, str], right: tuple[str, str], **kw: object
    ) -> None:
        lat_off = kw.pop("l")
        km = float(kw["km_m"])  # type: ignore[arg-type]
        lat, lon = self.f.latlon(np.array([km - KM0]), np.array([lat_off]))
        self.switches.append(
            {"switch_id": sid, "type": SwitchType.POINT.value, "a1_track": toe[0], "a1_end": toe[1]}
            | {"b1_track": left[0], "b1_end": left[1], "b2_track": right[0], "b2_end": right[1]}
            | {"line_code": LINE, "lat": float(lat[0]), "lon": float(lon[0])}
            | kw
        )
        both, none = Navigability.BOTH.value, Navigability.NONE.value
        for a, b, nav in ((toe, left, both), (toe, right, both), (left, right, none)):
            self.conns.append(
                {"track_a": a[0], "end_a": a[1], "track_b": b[0], "end_b": b[1], "navigability": nav, "switch_id": sid}
            )

    def group(self, bg: int, tid: str, line: str | None, track: str | None, km: float) -> None:
        for i in range(2):
            self.balises.append(
                {"balise_id": f"BG{bg}.{i}", "kind": BaliseKind.G.value, "line_code": line, "track": track}
                | {"km_actual_m": km + 3.0 * i, "km_equipment_m": km + 3.0 * i, "track_id": tid}
                | {"nid_c": NID_C, "nid_bg": bg, "n_pig": i, "n_total": 2}
            )


N_LOOP, R_LOOP = 10.0, 200.0
N_X = 10.0
N_JUNCTION, R_JUNCTION = 12.0, 300.0
BRANCH_LENGTH = 1500.0


def _loop(tables: _Tables, tid: str, l0: float, sign: float) -> None:
    a_lo, a_hi = TOES["loop_lo"] - KM0, TOES["loop_hi"] - KM0
    p = reverse_curves(a_lo, l0, LOOP_OUT, N_LOOP, R_LOOP, sign)
    alpha = math.atan(1.0 / N_LOOP)
    s = p.pieces[1][0]
    p.straight(a_hi - a_lo - 2 * extent(reverse_curves(0, 0, LOOP_OUT, N_LOOP, R_LOOP, sign)))
    p.arc(R_LOOP, -sign * alpha).straight(s).arc(R_LOOP, sign * alpha)
    tables.own(tid, tid.rsplit("-", 1)[1], TrackKind.STATION.value, p, f"Matoba station track {tid[-1]}")


def _branch_gis(tables: _Tables) -> None:
    alpha = math.atan(1.0 / N_JUNCTION)
    p = Path2D(TOES["junction"] - KM0, 0.0).arc(R_JUNCTION, alpha).straight(40.0)
    p.arc(500.0, math.radians(30.0) - alpha)
    p.straight(BRANCH_LENGTH - p.length)
    k = np.arange(0.0, BRANCH_LENGTH + STEP / 2, STEP)
    al = np.array([p.at(v)[:2] for v in k])
    lat, lon = tables.f.latlon(al[:, 0], al[:, 1])
    h = np.full(len(k), float(tables.f.height(np.array([TOES["junction"]]))[0]))
    tables.gis.append(
        pd.DataFrame({"line_code": BRANCH, "track": "S", "km_m": k, "lat": lat, "lon": lon, "height_m": h})
    )
    tables.features += path_features(f"{BRANCH}-S1", p)
    tables.tracks.append(
        {"track_id": f"{BRANCH}-S1", "line_code": BRANCH, "track": "S", "kind": TrackKind.MAIN.value}
        | {"km_begin_m": 0.0, "km_end_m": BRANCH_LENGTH, "length_m": BRANCH_LENGTH, "name": None}
    )


def network_tables(gis: pd.DataFrame, km_first: float, km_last: float) -> dict[str, pd.DataFrame]:
    """The network rows (tracks, connections, switches, track_points, track_feature_points), the
    G balises, the branch line's ``gis`` rows and its ``lines`` row, drawn on the sample's D/U
    grid (module docstring)."""
    t = _Tables(_Frame(gis))
    toe = TOES
    d_cuts = [km_first, toe["loop_lo"], toe["loop_hi"], toe["x1"], toe["x2"] + X_EXTENT, toe["junction"], km_last]
    u_cuts = [km_first, toe["loop_lo"], toe["loop_hi"], toe["x1"] + X_EXTENT, toe["x2"], km_last]
    for track, cuts in (("D", d_cuts), ("U", u_cuts)):
        for i in range(len(cuts) - 1):
            t.main(f"{LINE}-{track}{i + 1}", track, cuts[i], cuts[i + 1])
    _loop(t, f"{LINE}-3", 0.0, 1.0)
    _loop(t, f"{LINE}-4", -TRACK_SPACING, -1.0)
    r_x = radius_for_extent(X_EXTENT, TRACK_SPACING, N_X)
    for tid, a0, l0, sign in (("X1", toe["x1"], 0.0, -1.0), ("X2", toe["x2"], -TRACK_SPACING, 1.0)):
        p = reverse_curves(a0 - KM0, l0, TRACK_SPACING, N_X, r_x, sign)
        t.own(f"{LINE}-{tid}", None, TrackKind.CROSSOVER.value, p, f"crossover {tid}")
    _branch_gis(t)
    loop = {"switch_number": N_LOOP, "diverging_radius_m": R_LOOP}
    xo = {"switch_number": N_X, "diverging_radius_m": round(r_x, 1)}
    jn = {"switch_number": N_JUNCTION, "diverging_radius_m": R_JUNCTION}
    left, right = Side.LEFT.value, Side.RIGHT.value
    b, e = "begin", "end"
    sw = t.switch
    sw("W1", ("0420-D1", e), ("0420-3", b), ("0420-D2", b), km_m=toe["loop_lo"], l=0.0, diverging_side=left, **loop)
    sw("W2", ("0420-D3", b), ("0420-D2", e), ("0420-3", e), km_m=toe["loop_hi"], l=0.0, diverging_side=right, **loop)
    sw("W3", ("0420-U1", e), ("0420-U2", b), ("0420-4", b), km_m=toe["loop_lo"], l=-3.8, diverging_side=right, **loop)
    sw("W4", ("0420-U3", b), ("0420-4", e), ("0420-U2", e), km_m=toe["loop_hi"], l=-3.8, diverging_side=left, **loop)
    sw("W5", ("0420-D3", e), ("0420-D4", b), ("0420-X1", b), km_m=toe["x1"], l=0.0, diverging_side=right, **xo)
    sw(
        "W6",
        ("0420-U4", b),
        ("0420-U3", e),
        ("0420-X1", e),
        km_m=toe["x1"] + X_EXTENT,
        l=-3.8,
        diverging_side=right,
        **xo,
    )
    sw("W7", ("0420-U4", e), ("0420-X2", b), ("0420-U5", b), km_m=toe["x2"], l=-3.8, diverging_side=left, **xo)
    sw(
        "W8",
        ("0420-D5", b),
        ("0420-X2", e),
        ("0420-D4", e),
        km_m=toe["x2"] + X_EXTENT,
        l=0.0,
        diverging_side=left,
        **xo,
    )
    sw("W9", ("0420-D5", e), ("0421-S1", b), ("0420-D6", b), km_m=toe["junction"], l=0.0, diverging_side=left, **jn)
    groups: tuple[tuple[str, str, str | None, float], ...] = (
        ("0420-D1", LINE, "D", 20_700.0),  # before the station (D trains)
        ("0420-D2", LINE, "D", 20_840.0),  # beyond facing W1: through …
        ("0420-3", LINE, None, 20_860.0),  # … and diverging (loop 3)
        ("0420-U5", LINE, "U", 21_640.0),  # before the crossovers (U trains)
        ("0420-U2", LINE, "U", 21_277.0),  # beyond facing W4: through …
        ("0420-4", LINE, None, 21_257.0),  # … and diverging (loop 4)
        ("0420-D4", LINE, "D", 21_437.0),  # beyond facing W5: through …
        ("0420-X1", LINE, None, 21_420.0),  # … and diverging (crossover X1)
        ("0420-U3", LINE, "U", 21_417.0),  # beyond facing W6 (U trains): through
        ("0420-D6", LINE, "D", 21_740.0),  # beyond facing W9: through …
        ("0421-S1", BRANCH, "S", 40.0),  # … and diverging (the branch line)
    )
    for bg, group in enumerate(groups, start=1):
        t.group(bg, *group)
    return {
        "tracks": pd.DataFrame(t.tracks),
        "connections": pd.DataFrame(t.conns),
        "switches": pd.DataFrame(t.switches),
        "track_points": pd.concat(t.points, ignore_index=True),
        "track_feature_points": pd.DataFrame(t.features),
        "balises": pd.DataFrame(t.balises),
        "gis": pd.concat(t.gis, ignore_index=True),
        "lines": pd.DataFrame({"line_code": [BRANCH], "name": [BRANCH_NAME]}),
    }


def add_network(sources: Path, out: Path) -> None:
    """Write the sample network's source set with its station, crossovers and junction to
    ``out``: the line-only set in ``sources`` (its grid, S003 balises, feature points, lines)
    copied unchanged, plus the branch line's gis rows and lines row, the G balises and the
    network tables. ``python -m fieldlogs.simulate.networks.sample_junctions`` runs it alone, without
    refitting the line."""
    import shutil

    from dbtools.network import canonical
    from schemas.network import NETWORK_TABLES
    from schemas.tables import BALISES, LINES, TRACK_FEATURE_POINTS

    def write(table: Table, frame: pd.DataFrame, path: Path) -> None:
        cols = [c for c in table.column_names if c != "attributes_json"]
        canonical(table, frame)[cols].to_csv(path, index=False, lineterminator="\n")

    out.mkdir(exist_ok=True)
    for f in sources.glob("*.csv"):
        shutil.copyfile(f, out / f.name)
    own = (sources / "gis.csv").read_text(encoding="utf-8")
    gis = pd.read_csv(io.StringIO(own), dtype={"line_code": str, "track": str})
    line = gis[gis["line_code"] == LINE]
    net = network_tables(gis, float(line["km_m"].min()), float(line["km_m"].max()))
    branch = net["gis"].to_csv(index=False, header=False, lineterminator="\n")
    (out / "gis.csv").write_text(own + branch, encoding="utf-8", newline="\n")
    b = pd.read_csv(sources / "balises.csv", dtype={"line_code": str, "station_code": str, "track": str})
    write(BALISES, pd.concat([b, net["balises"]], ignore_index=True), out / "balises.csv")
    lines = pd.read_csv(sources / "lines.csv", dtype={"line_code": str})
    write(LINES, pd.concat([lines, net["lines"]], ignore_index=True), out / "lines.csv")
    for table in (*NETWORK_TABLES, TRACK_FEATURE_POINTS):
        write(table, net[table.name], out / f"{table.name}.csv")


if __name__ == "__main__":
    from dbtools.sample_network import sample_network_source_dir, sample_source_dir

    add_network(sample_source_dir(), sample_network_source_dir())
