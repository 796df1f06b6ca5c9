"""``db validate`` rules: a clean synthetic network has no findings; breaking one thing
produces exactly the finding of the rule that guards it (and nearly-broken does not)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.gis.geometry import Projector
from dbtools.network import Network, canonical, empty_frame
from dbtools.rules.config import ValidationConfig
from dbtools.rules.features import stencil_leak
from dbtools.sources import write_source_set
from dbtools.validate import validate_network, validate_path
from fieldlogs.simulate.networks.alignment import Alignment, Curve
from fieldlogs.simulate.networks.synthetic import LineSpec, Station, build_network, demo_line, random_alignment
from schemas.enums import Severity, Track
from schemas.findings import Finding
from schemas.tables import DB_TABLES, GIS, KM_BREAKS, LINES

P = Projector(9)


@pytest.fixture(scope="module")
def clean() -> Network:
    return build_network([demo_line()], P)


@pytest.fixture
def net(clean: Network) -> Network:
    """A private copy of the clean network, safe to break."""
    return Network({k: v.copy() for k, v in clean.tables.items()}, origin="test")


def run(net: Network, schema: bool = False, **config: float) -> list[Finding]:
    """Domain rules (plus the declarative schema checks with ``schema``)."""
    return validate_network(net, schema_checks=schema, config=ValidationConfig(**config))  # type: ignore[arg-type]


def of(findings: list[Finding], rule: str) -> list[Finding]:
    return [f for f in findings if f.rule == rule]


def only(findings: list[Finding], *rules: str) -> None:
    assert {f.rule for f in findings} == set(rules), [str(f) for f in findings]


def row(frame: pd.DataFrame, **where: object) -> int:
    """Index of the single row matching ``where``."""
    mask = np.ones(len(frame), dtype=bool)
    for k, v in where.items():
        mask &= (frame[k] == v).to_numpy(dtype=bool, na_value=False)
    (idx,) = np.flatnonzero(mask)
    return int(idx)


def move_gis(net: Network, line: str, track: str, km: np.ndarray | float, left_m: float) -> None:
    """Move the GIS points of ``km`` sideways (left of increasing km) by ``left_m``."""
    g = net.gis
    sel = np.flatnonzero((g["line_code"] == line).to_numpy() & (g["track"] == track).to_numpy())
    x, y = P.to_xy(g["lon"].to_numpy()[sel], g["lat"].to_numpy()[sel])
    h = np.arctan2(np.gradient(y), np.gradient(x))
    hit = np.isin(g["km_m"].to_numpy()[sel], np.atleast_1d(km))
    x[hit] -= left_m * np.sin(h[hit])
    y[hit] += left_m * np.cos(h[hit])
    lon, lat = P.to_lonlat(x[hit], y[hit])
    g.loc[sel[hit], "lon"] = lon
    g.loc[sel[hit], "lat"] = lat


# -------------------------------------------------------------------------- clean networks


def test_clean_network_has_no_findings(clean: Network) -> None:
    assert validate_network(clean) == []


def test_clean_varied_networks_have_no_findings() -> None:
    """Several zones, single track, sharp and gentle curves, curves without transitions."""
    rng = np.random.default_rng(11)
    specs = []
    for i, radii in enumerate([(250.0, 600.0), (600.0, 2000.0), (2000.0, 6000.0)]):
        a = random_alignment(rng, 6000.0, km0=20.0 * i * 37, radius_m=radii, x0=i * 40_000.0, y0=-i * 30_000.0)
        specs.append(LineSpec(f"{i + 1:04d}", "l", a, [Station("01", "s", a.km0 + 700.0)]))
    a = random_alignment(rng, 5000.0, km0=500.0, x0=-90_000.0)
    specs.append(LineSpec("0010", "single", a, [Station("01", "s", 2000.0)], tracks=(Track.SINGLE,)))
    bare = Alignment(3000.0, [Curve(500.0, 0.0, 300.0, 400.0, True), Curve(1500.0, 50.0, 200.0, 260.0, False)])
    specs.append(LineSpec("0011", "no transitions", bare, [Station("01", "s", 1500.0)]))
    for zone in (4, 9, 12):
        assert validate_network(build_network(specs, Projector(zone))) == []


def test_clean_source_set_and_db_have_no_findings(clean: Network, tmp_path: Path) -> None:
    src = write_source_set(clean, tmp_path / "src")
    assert validate_path(src) == []
    build_db(src, tmp_path / "net.sqlite")
    assert validate_path(tmp_path / "net.sqlite") == []


# -------------------------------------------------------------------------- schema


def test_radius_must_match_attribute(net: Network) -> None:
    fp = net.feature_points
    fp.loc[row(fp, feature_id="F001", track="D", seq=3), "radius_m"] = 0.0
    fp.loc[row(fp, feature_id="F002", track="D", seq=1), "radius_m"] = 300.0
    found = of(run(net), "schema.radius")
    assert [f.keys["seq"] for f in found] == [3, 1]
    assert all(f.severity == Severity.ERROR and f.column == "radius_m" for f in found)


def test_infinite_number_in_db(net: Network) -> None:
    b = net.balises
    b.loc[row(b, balise_id="0900-D-C001"), "km_equipment_m"] = np.inf
    only(run(net, schema=True), "schema.not_finite")


def test_lat_lon_outside_operating_area(net: Network) -> None:
    g = net.gis
    g.loc[5, "lat"] = 12.0
    found = run(net, schema=True)
    assert of(found, "schema.range") and of(found, "schema.range")[0].column == "lat"
    assert of(found, "gis.km_step")  # the point is left out of the grid: a hole


# -------------------------------------------------------------------------- balises


def test_pair_needs_one_i1_and_one_i2(net: Network) -> None:
    b = net.balises
    extra = b.iloc[[row(b, balise_id="0900-02-D-I1")]].assign(balise_id="0900-02-D-I1b")
    net.tables["balises"] = pd.concat([b.drop(index=row(b, balise_id="0900-03-U-I2")), extra], ignore_index=True)
    found = of(run(net), "balise.pair_count")
    assert sorted((f.keys["station_code"], f.keys["track"], tuple(f.value)) for f in found) == [
        ("02", "D", (2, 1)),
        ("03", "U", (1, 0)),
    ]


@pytest.mark.parametrize(("shift", "flagged"), [(0.45, False), (0.6, True), (-0.6, True)])
def test_pair_spacing(net: Network, shift: float, flagged: bool) -> None:
    b = net.balises
    b.loc[row(b, balise_id="0900-01-D-I2"), "km_actual_m"] += shift
    found = run(net)
    if flagged:
        only(found, "balise.pair_spacing")
        assert found[0].keys == {"line_code": "0900", "station_code": "01", "track": "D"}
        assert found[0].value == pytest.approx(5 + shift) and found[0].limit == [4.5, 5.5]
    else:
        assert found == []


@pytest.mark.parametrize("track", ["D", "U"])
def test_pair_order_follows_running_direction(net: Network, track: str) -> None:
    b = net.balises
    i1, i2 = row(b, balise_id=f"0900-02-{track}-I1"), row(b, balise_id=f"0900-02-{track}-I2")
    b.loc[[i1, i2], "km_actual_m"] = b.loc[[i2, i1], "km_actual_m"].to_numpy()
    only(run(net), "balise.pair_order", "balise.dist_from_initial")  # C distances now 5 m off


def test_c_balise_needs_existing_pair_and_fields(net: Network) -> None:
    b = net.balises
    b.loc[row(b, balise_id="0900-D-C001"), "station_code"] = "99"
    b.loc[row(b, balise_id="0900-D-C002"), "signal_type"] = pd.NA
    b.loc[row(b, balise_id="0900-D-C003"), "dist_from_initial_m"] = np.nan
    found = run(net)
    only(found, "balise.c_pair", "balise.c_fields")
    assert [f.keys["balise_id"] for f in of(found, "balise.c_pair")] == ["0900-D-C001"]
    assert {f.keys["balise_id"]: f.column for f in of(found, "balise.c_fields")} == {
        "0900-D-C002": "signal_type",
        "0900-D-C003": "dist_from_initial_m",
    }


def test_initial_balise_with_c_fields_is_a_warning(net: Network) -> None:
    b = net.balises
    b.loc[row(b, balise_id="0900-01-D-I1"), "signal_type"] = "home"
    found = run(net)
    only(found, "balise.initial_fields")
    assert found[0].severity == Severity.WARNING


@pytest.mark.parametrize(("offset", "flagged"), [(300.0, True), (-500.0, True), (501.0, False)])
def test_same_signal_type_within_window_is_ambiguous(net: Network, offset: float, flagged: bool) -> None:
    b = net.balises
    c = b.iloc[[row(b, balise_id="0900-D-C001")]].copy()  # block, pair 01 D, 1750 m after I1
    c["balise_id"] = "0900-D-C099"
    c["km_actual_m"] += offset
    c["km_equipment_m"] += offset
    c["dist_from_initial_m"] += offset
    net.tables["balises"] = pd.concat([b, c], ignore_index=True)
    found = run(net)
    if flagged:
        only(found, "balise.ambiguous")
        assert found[0].value == pytest.approx(abs(offset)) and found[0].limit == 500.0
        assert {found[0].keys["balise_id"], found[0].keys["other_balise_id"]} == {"0900-D-C001", "0900-D-C099"}
    else:
        assert found == []


def test_different_signal_types_are_not_ambiguous(net: Network) -> None:
    b = net.balises
    c = b.iloc[[row(b, balise_id="0900-D-C001")]].assign(balise_id="0900-D-C099", signal_type="shunt")
    net.tables["balises"] = pd.concat([b, c], ignore_index=True)
    assert run(net) == []


@pytest.mark.parametrize(("delta", "flagged"), [(0.8, False), (5.0, True)])
def test_dist_from_initial_is_travel_distance(net: Network, delta: float, flagged: bool) -> None:
    b = net.balises
    b.loc[row(b, balise_id="0900-U-C003"), "dist_from_initial_m"] += delta
    found = run(net)
    if flagged:
        only(found, "balise.dist_from_initial")
        assert found[0].severity == Severity.WARNING and found[0].limit == 1750.0
    else:
        assert found == []


def test_c_balise_behind_its_pair(net: Network) -> None:
    b = net.balises
    i = row(b, balise_id="0900-U-C005")  # U track: governed by pair 02 at km 4750, runs toward lower km
    b.loc[i, ["km_actual_m", "km_equipment_m", "dist_from_initial_m"]] = [5000.0, 5000.0, 250.0]
    found = run(net)
    only(found, "balise.c_direction")
    assert found[0].value == pytest.approx(-250.0)


def test_balise_outside_gis(net: Network) -> None:
    b = net.balises
    b.loc[row(b, balise_id="0900-04-D-I1"), ["km_actual_m"]] = 20_000.0
    b.loc[row(b, balise_id="0900-04-D-I2"), ["km_actual_m"]] = 20_005.0
    b.loc[row(b, balise_id="0900-03-U-I1"), "track"] = "S"
    found = of(run(net), "balise.outside_gis")
    assert sorted(f.keys["balise_id"] for f in found) == ["0900-03-U-I1", "0900-04-D-I1", "0900-04-D-I2"]
    assert any("no GIS grid for line 0900 track S" in f.message for f in found)


# -------------------------------------------------------------------------- GIS


def test_km_off_the_20m_grid(net: Network) -> None:
    g = net.gis
    g.loc[row(g, track="D", km_m=5000.0), "km_m"] = 5007.0
    found = run(net)
    assert [f.value for f in of(found, "gis.km_grid")] == [5007.0]
    assert {f.rule for f in found} <= {"gis.km_grid", "gis.km_step", "gis.step_length"}


def test_km_gap_needs_a_km_break(net: Network) -> None:
    g = net.gis
    net.tables["gis"] = g.drop(index=row(g, track="U", km_m=6000.0)).reset_index(drop=True)
    found = run(net)
    only(found, "gis.km_step")
    assert found[0].keys == {"line_code": "0900", "track": "U", "km_m": 6020.0} and found[0].value == 40.0
    breaks = pd.DataFrame(
        {"line_code": ["0900", "0900"], "track": ["U", "D"], "km_from_m": [5980.0, 100.0], "km_to_m": [6020.0, 120.0]}
    )
    net.tables["km_breaks"] = canonical(KM_BREAKS, breaks)
    found = run(net)
    only(found, "gis.km_break_unused")  # the U gap is listed; the D row matches nothing
    assert found[0].keys["track"] == "D" and found[0].severity == Severity.WARNING


def test_km_break_skips_the_step_length_check() -> None:
    """A real km break: km jumps by 1 000 m while the points stay 20 m apart."""
    a = random_alignment(np.random.default_rng(3), 4000.0, km0=0.0)
    spec = LineSpec("0500", "break", a, [], tracks=(Track.SINGLE,))
    net = build_network([spec], P)
    g = net.gis
    g.loc[g["km_m"] > 2000.0, "km_m"] += 1000.0
    net.tables["feature_points"] = net.feature_points.iloc[0:0]
    only(validate_network(net), "gis.km_step", "gis.step_length")
    net.tables["km_breaks"] = canonical(
        KM_BREAKS, pd.DataFrame({"line_code": ["0500"], "track": ["S"], "km_from_m": [2000.0], "km_to_m": [3020.0]})
    )
    assert validate_network(net) == []


@pytest.mark.parametrize(("along_m", "flagged"), [(0.3, False), (1.5, True)])
def test_step_length_against_km(net: Network, along_m: float, flagged: bool) -> None:
    g = net.gis
    i = row(g, track="D", km_m=5000.0)
    nxt = row(g, track="D", km_m=5020.0)
    # slide the point along the track toward its successor
    f = along_m / 20.0
    for c in ("lat", "lon"):
        g.loc[i, c] = g.loc[i, c] + f * (g.loc[nxt, c] - g.loc[i, c])
    found = run(net)
    if flagged:
        only(found, "gis.step_length")
        assert sorted(round(f.value, 1) for f in found) == [18.5, 21.5]
    else:
        assert found == []


def test_spike(net: Network) -> None:
    move_gis(net, "0900", "D", 5000.0, left_m=3.0)
    found = run(net)
    spikes = of(found, "gis.spike")
    assert [f.keys["km_m"] for f in spikes] == [4980.0, 5000.0, 5020.0]
    assert max(f.value for f in spikes) == pytest.approx(2 * np.arctan(3 / 20), abs=0.02)  # ± the curve
    assert {f.rule for f in found} == {"gis.spike"}


def test_small_wiggle_is_not_a_spike(net: Network) -> None:
    move_gis(net, "0900", "D", 5000.0, left_m=0.5)
    assert run(net) == []


def _offset_u(spec: LineSpec, u_offset: float) -> LineSpec:
    offsets = {Track.DOWN.value: 1.9, Track.UP.value: u_offset}
    spec.offset = lambda track: offsets[str(track)]  # type: ignore[method-assign]
    return spec


@pytest.mark.parametrize(
    ("u_offset", "severity"), [(-1.9, None), (-1.7, None), (-1.5, Severity.WARNING), (-0.4, Severity.ERROR)]
)
def test_track_spacing(u_offset: float, severity: Severity | None) -> None:
    net = build_network([_offset_u(demo_line(), u_offset)], P)
    found = validate_network(net)
    if severity is None:
        assert found == []
        return
    only(found, "gis.track_spacing")
    assert len(found) == 1  # one finding for the whole stretch
    assert found[0].severity == severity
    assert found[0].value == pytest.approx(1.9 - u_offset, abs=0.02)
    assert "km 1k000.0–13k000.0 (601 points)" in found[0].message


@pytest.mark.parametrize(("angle", "flagged"), [(0.05, False), (0.0, True)])
def test_track_spacing_only_where_parallel(angle: float, flagged: bool) -> None:
    """U leaves D at a turnout: close together there, but not parallel (angle 0.05 rad)."""
    km = np.arange(0.0, 401.0, 20.0)
    frames = []
    for track, x, y in (("D", km, np.zeros_like(km)), ("U", km * np.cos(angle), -2.0 - km * np.sin(angle))):
        lon, lat = P.to_lonlat(x, y)
        frames.append(pd.DataFrame({"line_code": "0700", "track": track, "km_m": km, "lat": lat, "lon": lon}))
    found = validate_network(gis_only(pd.concat(frames)))
    assert {f.rule for f in found} == ({"gis.track_spacing"} if flagged else set())


def gis_only(gis: pd.DataFrame) -> Network:
    tables = {t.name: empty_frame(t) for t in DB_TABLES}
    tables["gis"] = canonical(GIS, gis)
    tables["lines"] = canonical(LINES, pd.DataFrame({"line_code": gis["line_code"].unique()}))
    return Network(tables)


# -------------------------------------------------------------------------- feature points


def test_feature_needs_six_rows(net: Network) -> None:
    fp = net.feature_points
    net.tables["feature_points"] = fp.drop(index=row(fp, feature_id="F002", track="U", seq=4))
    found = run(net)
    only(found, "feature.rows")
    assert found[0].keys == {"line_code": "0900", "track": "U", "feature_id": "F002"}
    assert found[0].value == [1, 2, 3, 5, 6]


def test_feature_attribute_pattern(net: Network) -> None:
    fp = net.feature_points
    fp.loc[row(fp, feature_id="F001", track="D", seq=2), "attribute"] = "straight"
    fp.loc[row(fp, feature_id="F001", track="D", seq=6), "attribute"] = "straight"
    found = run(net)
    only(found, "feature.pattern")
    assert [(f.keys["seq"], f.value) for f in found] == [(2, "straight"), (6, "straight")]


@pytest.mark.parametrize("track", ["D", "U"])
def test_feature_km_order(net: Network, track: str) -> None:
    fp = net.feature_points
    i3, i4 = row(fp, feature_id="F002", track=track, seq=3), row(fp, feature_id="F002", track=track, seq=4)
    fp.loc[[i3, i4], "km_m"] = fp.loc[[i4, i3], "km_m"].to_numpy()
    found = run(net)
    only(found, "feature.order")
    assert found[0].limit == ("decreasing" if track == "U" else "increasing")


def test_feature_straight_too_short(net: Network) -> None:
    fp = net.feature_points
    fp.loc[row(fp, feature_id="F001", track="D", seq=1), "km_m"] += 5.0
    found = run(net)
    only(found, "feature.straight_length")
    assert found[0].value == pytest.approx(15.0) and found[0].limit == 20.0


def test_feature_outside_gis(net: Network) -> None:
    fp = net.feature_points
    fp.loc[row(fp, feature_id="F001", track="D", seq=1), "km_m"] = 900.0  # GIS starts at km 1000
    found = run(net)
    only(found, "feature.outside_gis")
    assert found[0].keys["seq"] == 1 and found[0].limit == [1000.0, 13000.0]


@pytest.mark.parametrize("track", ["D", "U"])
def test_feature_direction(net: Network, track: str) -> None:
    fp = net.feature_points
    i = row(fp, feature_id="F003", track=track, seq=3)
    fp.loc[i, "attribute"] = {"left": "right", "right": "left"}[fp.loc[i, "attribute"]]
    found = run(net)
    only(found, "feature.direction")
    assert found[0].keys["track"] == track


@pytest.mark.parametrize(("factor", "flagged"), [(1.15, False), (0.87, False), (1.3, True), (0.8, True)])
def test_feature_radius(net: Network, factor: float, flagged: bool) -> None:
    fp = net.feature_points
    i = row(fp, feature_id="F001", track="U", seq=3)
    fp.loc[i, "radius_m"] *= factor
    found = run(net)
    if flagged:
        only(found, "feature.radius")
        assert found[0].column == "radius_m"
    else:
        assert found == []


def test_feature_straight_is_curved_on_gis(net: Network) -> None:
    """The whole feature shifted 60 m forward: its entry straight now lies in the curve."""
    fp = net.feature_points
    sel = ((fp["feature_id"] == "F001") & (fp["track"] == "D")).to_numpy()
    fp.loc[sel, "km_m"] += 60.0
    found = run(net)
    straight = of(found, "feature.straight")
    assert [f.keys["seq"] for f in straight] == [1]
    assert straight[0].value < straight[0].limit


def test_stencil_leak_hand_computed() -> None:
    # clothoid longer than the grid step: y(h) = κh³/6L → κh/6L
    assert stencil_leak(np.array([1 / 300]), np.array([36.0]), 20.0)[0] == pytest.approx(20 / (6 * 36 * 300))
    # no transition: the arc starts at the vertex, y = κh²/2 → κ/2
    assert stencil_leak(np.array([1 / 400]), np.array([0.0]), 20.0)[0] == pytest.approx(1 / 800)


# -------------------------------------------------------------------------- source sets


def test_source_findings_name_file_and_line(clean: Network, tmp_path: Path) -> None:
    """Rows shuffled in the file: the finding still points at the line that holds the row."""
    src = write_source_set(clean, tmp_path / "src")
    path = src / "balises.csv"
    lines = path.read_text().splitlines()
    body = lines[1:]
    np.random.default_rng(5).shuffle(body)
    target = next(i for i, ln in enumerate(body) if ln.startswith("0900-02-U-I2,"))
    cells = body[target].split(",")
    cells[6] = str(float(cells[6]) - 2.0)  # km_actual_m: pair now 7 m apart
    body[target] = ",".join(cells)
    path.write_text("\n".join([lines[0], *body]) + "\n")
    found = validate_path(src)
    only(found, "balise.pair_spacing")
    assert found[0].file == str(path) and found[0].row == target + 2
    assert found[0].to_dict()["row"] == target + 2


def test_findings_are_capped_per_rule(net: Network) -> None:
    g = net.gis
    g.loc[(g["track"] == "D").to_numpy(), "km_m"] += 1.0  # every D km leaves the 20 m grid
    found = of(run(net, max_findings_per_rule=10), "gis.km_grid")
    assert len(found) == 11 and found[-1].value == 601
