"""``db import --format railml``: track topology (tracks, connections, switches) and balise
groups (kind G) from railML 2.x and 3.x, and the railML 3 export of them (round trip).

The hand-written files in tests/data/railml/ state their layout in a comment; the expected
rows below are worked out from that layout by hand (module docs of
:mod:`dbtools.interchange.topology2` / ``topology3`` / ``balise_groups``)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.interchange.export import ExportFormat, export_network
from dbtools.interchange.importer import import_railml
from dbtools.validate import validate_path
from schemas.errors import FindingsError

DATA = Path(__file__).resolve().parents[2] / "data" / "railml"
FINLAND = DATA / "Track-007_28-47.railml.xml"
FI = "x.x.xxx.LIVI.INFRA.41.1000{:02d}3158071"  # Finnish km piece → track id


def _rows(folder: Path, table: str) -> list[dict[str, object]]:
    p = folder / f"{table}.csv"
    if not p.is_file():
        return []
    frame = pd.read_csv(p, dtype=str, keep_default_na=False)
    return frame.to_dict("records")


def _links(folder: Path) -> set[tuple[frozenset[tuple[str, str]], str, str]]:
    """Connections as (the two ends, navigability, switch) — a/b order does not matter for
    both/none."""
    return {
        (frozenset({(r["track_a"], r["end_a"]), (r["track_b"], r["end_b"])}), r["navigability"], r["switch_id"])
        for r in _rows(folder, "connections")
    }


def _link(a: str, ea: str, b: str, eb: str, nav: str, sw: str) -> tuple[frozenset[tuple[str, str]], str, str]:
    return frozenset({(a, ea), (b, eb)}), nav, sw


# ---------------------------------------------------------------------------- the Finnish file


@pytest.fixture(scope="module")
def finland(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:  # type: ignore[type-arg]
    out = tmp_path_factory.mktemp("fi") / "fi"
    r = import_railml(FINLAND, out)
    return out, r.findings


def test_finnish_balises_are_groups_on_their_tracks(finland: tuple[Path, list]) -> None:  # type: ignore[type-arg]
    out, findings = finland
    b = pd.read_csv(out / "balises.csv", dtype=str)
    tracks = pd.read_csv(out / "tracks.csv", dtype=str)
    assert len(b) == 76 and set(b["kind"]) == {"G"} and b["nid_bg"].isna().all()
    assert set(b["track_id"]) <= set(tracks["track_id"])
    # 31 pairs (same pos, same dir, numbered n and n + 2) and 14 single balises
    sizes = Counter(b.groupby("n_total").size().to_dict())
    assert b.groupby("n_total").size().to_dict() == {"1": 14, "2": 62}, sizes
    assert sum(f.rule == "railml.balise_identity" for f in findings) == 45
    by_id = b.set_index("balise_id")
    # 55012 (pos 1094 on the 1000 m piece km 40003–41003, absPos 41097) lies on the next piece
    moved = by_id.loc["x.x.xxx.LIVI.INFRA.11.1211980"]
    assert moved["track_id"] == FI.format(42) and float(moved["km_actual_m"]) == 41097.0
    assert any(
        f.rule == "railml.position" and "placed on the track that continues there" in f.message and f.row == 365
        for f in findings
    )
    # a pair at one position read "up": N_PIG by name (55025 before 55027: the file gives no order)
    pair = by_id.loc[["x.x.xxx.LIVI.INFRA.11.1212114", "x.x.xxx.LIVI.INFRA.11.1212099"]]
    assert pair["n_pig"].tolist() == ["0", "1"] and set(pair["n_total"]) == {"2"}
    # every track's km range holds its balises, but for the four past the end of the last
    # piece (km 47005: no track continues there in the file; kept by their absPos)
    t = tracks.set_index("track_id")
    km = b["km_actual_m"].astype(float)
    lo, hi = b["track_id"].map(t["km_begin_m"].astype(float)), b["track_id"].map(t["km_end_m"].astype(float))
    outside = b[~((km >= lo) & (km <= hi))]
    assert set(outside["track_id"]) == {FI.format(47)} and sorted(outside["km_actual_m"].astype(float)) == [
        47162.0,
        47162.0,
        47566.0,
        47566.0,
    ]


def test_finnish_tracks_connections_switches(finland: tuple[Path, list]) -> None:  # type: ignore[type-arg]
    out, findings = finland
    tracks = pd.read_csv(out / "tracks.csv", dtype=str).set_index("track_id")
    # 19 km pieces, three of them cut at the switches inside them (31 at 235, 563, 812; 33 at 280, 417; 38 at 879)
    assert len(tracks) == 19 + 6 and set(tracks["kind"]) == {"main"} and set(tracks["line_code"]) == {"line_007_28_47"}
    assert tracks.loc[FI.format(41), ["km_begin_m", "km_end_m", "length_m", "name"]].tolist() == [
        "40003.0",
        "41003.0",
        "1000.0",
        "007 - 41",
    ]
    links = _links(out)
    assert len(links) == 18 + 6  # the pieces in a row: 28 … 38, 40 … 47 (no 39 in the file), each cut joined
    assert (
        _link(FI.format(38) + "@879", "end", FI.format(40), "begin", "both", "") in links
    )  # the @ref-names-a-track quirk
    assert any(f.rule == "railml.quirk" and "tbc_40" in f.message and f.row == 336 for f in findings)
    # the 6 switches lie inside the km pieces and name only track sections outside the file: the
    # piece runs straight through each, whose diverging port is left empty (and said so)
    sw = pd.read_csv(out / "switches.csv", dtype=str).set_index("switch_id")
    assert len(sw) == 6 and set(sw["type"]) == {"point"}
    assert sw["a1_track"].notna().all() and (sw["b1_track"].isna() ^ sw["b2_track"].isna()).all()
    # KYT V0657 at 31+235: its branch leaves "outgoing" to the right, so the toe is the piece before
    v0657 = sw.loc["x.x.xxx.LIVI.INFRA.24.102930"]
    assert (v0657["a1_track"], v0657["a1_end"]) == (FI.format(31), "end")
    assert (v0657["b1_track"], v0657["b1_end"]) == (FI.format(31) + "@235", "begin")
    assert v0657["diverging_side"] == "right" and float(v0657["km_m"]) == 31235.0 and v0657["name"] == "KYT V0657"
    open_ = [f for f in findings if f.rule == "railml.switch_open_port"]
    assert len(open_) == 6 and all("outside the file" in f.message for f in open_)
    assert not [f for f in findings if f.rule == "railml.switch_open"]
    dangling = [f for f in findings if f.rule == "railml.dangling_ref"]
    assert len(dangling) == 3 + 18
    first = next(f for f in dangling if f.row == 56)
    assert "tbc_28" in first.message and "'undefined'" in first.message
    assert any(f.row == 104 and "tbc_x.x.xxx.LIVI.INFRA.44.463745" in f.message for f in dangling)
    unmapped = Counter(f.message.split(" not imported")[0] for f in findings if f.rule == "railml.unmapped")
    assert unmapped == {"signal": 34, "infraAttributes": 4, "speedChange": 4, "visualization": 1}


def test_finnish_result_builds_and_validates_without_crash(finland: tuple[Path, list], tmp_path: Path) -> None:  # type: ignore[type-arg]
    out, _ = finland
    with pytest.raises(FindingsError) as ei:  # the file has no coordinates: no GIS grid to build on
        build_db(out, tmp_path / "fi.sqlite", db_version="t")
    assert {f.rule for f in ei.value.findings if f.severity == "error"} == {"schema.empty_table"}
    findings = validate_path(out)
    # what the extract lacks, said by the rules: no grid; balise groups without an ETCS identity
    # (balise.group_fields); four balises beyond the last km piece (topology.balise_position)
    allowed = {"schema.empty_table", "balise.outside_gis", "balise.group_fields", "topology.balise_position"}
    assert {f.rule for f in findings if f.severity == "error"} <= allowed


def test_nothing_imported_is_an_error(tmp_path: Path) -> None:
    """A map naming initial pairs the file does not have: every balise would need a pair, none
    is written — exit 1, nothing written."""
    m = tmp_path / "pairs.toml"
    m.write_text('[initial_pairs]\n"none" = "00"\n', encoding="utf-8")
    with pytest.raises(FindingsError) as ei:
        import_railml(FINLAND, tmp_path / "out", line_map=m)
    errors = [f for f in ei.value.findings if f.severity == "error"]
    assert [f.rule for f in errors] == ["railml.nothing_imported"] and "76 balises" in errors[0].message
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------- hand-written files

JUNCTION_TRACKS = [
    ["T1", "J1", "S", "main", "0.0", "1000.0", "1000.0", "main 1"],
    ["T2", "J1", "S", "main", "1000.0", "2000.0", "1000.0", "main 2"],
    ["T3", "", "", "connecting", "", "", "300.0", "branch"],
]


def _junction_expected(t1: str, t2: str, t3: str) -> tuple[set, dict, list]:  # type: ignore[type-arg]
    links = {
        _link(t1, "end", t2, "begin", "both", "W1"),
        _link(t1, "end", t3, "begin", "both", "W1"),
        _link(t2, "begin", t3, "begin", "none", "W1"),
    }
    switch = {
        "switch_id": "W1",
        "type": "point",
        "a1_track": t1,
        "a1_end": "end",
        "b1_track": t2,
        "b1_end": "begin",
        "b2_track": t3,
        "b2_end": "begin",
        "diverging_side": "right",
        "diverging_radius_m": "300.0",
        "diverging_speed_kmh": "40.0",
        "line_code": "J1",
        "km_m": "1000.0",
        "name": "W1",
    }
    balises = [
        ["B1", "G", "J1", "S", "1100.0", t2, "230", "77", "0", "2"],
        ["B2", "G", "J1", "S", "1103.0", t2, "230", "77", "1", "2"],
    ]
    return links, switch, balises


def _check_junction(out: Path, t1: str, t2: str, t3: str, number: str) -> None:
    links, switch, balises = _junction_expected(t1, t2, t3)
    cols = ["track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m", "name"]
    got = [[r[c] for c in cols] for r in _rows(out, "tracks")]
    assert got == [[{"T1": t1, "T2": t2, "T3": t3}.get(x, x) for x in row] for row in JUNCTION_TRACKS]
    assert _links(out) == links
    (sw,) = _rows(out, "switches")
    assert {k: sw[k] for k in switch} == switch and sw["switch_number"] == number
    bcols = [
        "balise_id",
        "kind",
        "line_code",
        "track",
        "km_actual_m",
        "track_id",
        "nid_c",
        "nid_bg",
        "n_pig",
        "n_total",
    ]
    assert [[r[c] for c in bcols] for r in _rows(out, "balises")] == balises


def test_railml2_junction_exact_rows_build_and_validate(tmp_path: Path) -> None:
    out = tmp_path / "j"
    r = import_railml(DATA / "junction-2.4.railml.xml", out)
    _check_junction(out, "T1", "T2", "T3", "9.0")  # 1:9 from @model
    (d,) = [f for f in r.findings if f.rule == "railml.dangling_ref"]
    assert d.row == 50 and "'t9_begin'" in d.message and d.keys["id"] == "c_t3e"
    (sw,) = _rows(out, "switches")
    assert (float(sw["lat"]), float(sw["lon"])) == (60.0, 25.017966305810422)  # its geoCoord
    assert not [f for f in r.findings if f.rule == "railml.unmapped"]
    db = build_db(out, tmp_path / "j.sqlite", db_version="t")
    assert not [f for f in validate_path(tmp_path / "j.sqlite") if f.severity == "error"]
    assert db is not None


def test_railml3_junction_exact_rows(tmp_path: Path) -> None:
    out = tmp_path / "j3"
    r = import_railml(DATA / "junction-3.2.railml.xml", out)
    _check_junction(out, "ne1", "ne2", "ne3", "")
    (d,) = [f for f in r.findings if f.rule == "railml.dangling_ref"]
    assert "nr9" in d.message and "'ne9'" in d.message and d.row == 46
    assert not [f for f in r.findings if f.rule == "railml.unmapped"]


CROSSOVER_MAP = (
    '[tracks.TD1]\nline_code = "X1"\ntrack = "D"\n[tracks.TD2]\nline_code = "X1"\ntrack = "D"\n'
    '[tracks.TU1]\nline_code = "X1"\ntrack = "U"\n[tracks.TU2]\nline_code = "X1"\ntrack = "U"\n'
)


def test_railml2_crossover_and_a_switch_inside_a_track(tmp_path: Path) -> None:
    m = tmp_path / "map.toml"
    m.write_text(CROSSOVER_MAP, encoding="utf-8")
    out = tmp_path / "x"
    import_railml(DATA / "crossover-2.4.railml.xml", out, line_map=m)
    cols = ["track_id", "track", "kind", "km_begin_m", "km_end_m", "length_m"]
    assert [[r[c] for c in cols] for r in _rows(out, "tracks")] == [
        ["TD1", "D", "main", "0.0", "500.0", "500.0"],
        ["TD2", "D", "main", "500.0", "1000.0", "500.0"],
        ["TU1", "U", "main", "0.0", "550.0", "550.0"],
        ["TU2", "U", "main", "550.0", "750.0", "200.0"],  # cut at S3 (pos 200)
        ["TU2@200", "U", "main", "750.0", "1000.0", "250.0"],
        ["X", "", "crossover", "", "", "50.0"],
        ["Y", "", "siding", "", "", "120.0"],
    ]
    assert _links(out) == {
        _link("TD1", "end", "TD2", "begin", "both", "S1"),
        _link("TD1", "end", "X", "begin", "both", "S1"),
        _link("TD2", "begin", "X", "begin", "none", "S1"),
        # S2: X merges into U from the left seen in rising km → seen from the toe (TU2's
        # begin, facing falling km) it diverges to the right
        _link("TU2", "begin", "TU1", "end", "both", "S2"),
        _link("TU2", "begin", "X", "end", "both", "S2"),
        _link("TU1", "end", "X", "end", "none", "S2"),
        _link("TU2", "end", "TU2@200", "begin", "both", "S3"),
        _link("TU2", "end", "Y", "begin", "both", "S3"),
        _link("TU2@200", "begin", "Y", "begin", "none", "S3"),
    }
    ports = ["switch_id", "a1_track", "a1_end", "b1_track", "b1_end", "b2_track", "b2_end", "diverging_side", "km_m"]
    assert [[r[c] for c in ports] for r in _rows(out, "switches")] == [
        ["S1", "TD1", "end", "TD2", "begin", "X", "begin", "right", "500.0"],
        ["S2", "TU2", "begin", "TU1", "end", "X", "end", "right", "550.0"],
        ["S3", "TU2", "end", "Y", "begin", "TU2@200", "begin", "left", "750.0"],
    ]


@pytest.mark.parametrize("name", ["junction-2.4.railml.xml", "crossover-2.4.railml.xml"])
def test_railml3_export_round_trip(name: str, tmp_path: Path) -> None:
    """export → import gives the same tracks, connections, switches and G balises."""
    m = tmp_path / "map.toml"
    m.write_text(CROSSOVER_MAP if name.startswith("crossover") else "", encoding="utf-8")
    src = tmp_path / "src"
    import_railml(DATA / name, src, line_map=m)
    build_db(src, tmp_path / "a.sqlite", db_version="t")
    export_network(tmp_path / "a.sqlite", tmp_path / "a.railml", ExportFormat.railml)
    back = tmp_path / "back"
    r = import_railml(tmp_path / "a.railml", back)
    assert not [f for f in r.findings if f.rule in ("railml.unmapped", "railml.switch_open", "railml.dangling_ref")]
    for table in ("tracks", "connections", "switches", "balises"):
        assert _rows(back, table) == _rows(src, table), table


def test_railml2_single_slip(tmp_path: Path) -> None:
    out = tmp_path / "d"
    import_railml(DATA / "diamond-2.4.railml.xml", out)
    (sw,) = _rows(out, "switches")
    ports = [sw[f"{p}_{c}"] for p in ("a1", "b1", "a2", "b2") for c in ("track", "end")]
    assert sw["type"] == "single_slip" and ports == ["P1", "end", "P2", "begin", "Q1", "end", "Q2", "begin"]
    assert _links(out) == {
        _link("P1", "end", "P2", "begin", "both", "C1"),  # a1–b1
        _link("Q1", "end", "Q2", "begin", "both", "C1"),  # a2–b2
        _link("P1", "end", "Q2", "begin", "both", "C1"),  # the slip a1–b2
        _link("Q1", "end", "P2", "begin", "none", "C1"),
        _link("P1", "end", "Q1", "end", "none", "C1"),
        _link("P2", "begin", "Q2", "begin", "none", "C1"),
    }
    assert {r["kind"] for r in _rows(out, "tracks")} == {"connecting"}  # on no line, no @type


def test_railml3_crossover_and_crossing(tmp_path: Path) -> None:
    out = tmp_path / "x3"
    import_railml(DATA / "crossover-3.2.railml.xml", out)
    ports = ["switch_id", "type", "a1_track", "a1_end", "b1_track", "b1_end", "b2_track", "b2_end"]
    ports += ["a2_track", "a2_end", "diverging_side"]
    assert [[r[c] for c in ports] for r in _rows(out, "switches")] == [
        ["C1", "crossing", "P1", "end", "P2", "begin", "Q2", "begin", "Q1", "end", ""],
        ["S1", "point", "D1", "end", "D2", "begin", "X", "begin", "", "", "right"],
        ["S2", "point", "U2", "begin", "U1", "end", "X", "end", "", "", "right"],  # opposite continueCourse
    ]
    links = _links(out)
    assert _link("U1", "end", "X", "end", "none", "S2") in links  # the branches' relation, made
    assert _link("Q1", "end", "Q2", "begin", "AB", "C1") in links and len(links) == 8


def test_railml3_aggregate_netelements_are_not_tracks(tmp_path: Path) -> None:
    """A meso-level netElement (a collection of micro ones) and its relations are no tracks."""
    text = (DATA / "junction-3.2.railml.xml").read_text(encoding="utf-8")
    text = text.replace(
        "      </netElements>",
        '        <netElement id="m1"><elementCollectionUnordered id="ecu1">'
        '<elementPart ref="ne1"/><elementPart ref="ne2"/></elementCollectionUnordered></netElement>\n'
        '        <netElement id="m2"><elementCollectionUnordered id="ecu2">'
        '<elementPart ref="ne3"/></elementCollectionUnordered></netElement>\n'
        "      </netElements>",
    ).replace(
        "      </netRelations>",
        '        <netRelation id="nrm" positionOnA="1" positionOnB="0" navigability="Both">'
        '<elementA ref="m1"/><elementB ref="m2"/></netRelation>\n      </netRelations>',
    )
    src = tmp_path / "meso.railml"
    src.write_text(text, encoding="utf-8")
    out = tmp_path / "m"
    r = import_railml(src, out)
    _check_junction(out, "ne1", "ne2", "ne3", "")
    assert not [f for f in r.findings if f.rule == "railml.unmapped"]


# ------------------------------------------------- one physical switch, every railML 2 description


def _track2(ident: str, at_switch: str, conn: str) -> str:
    """A 100 m railML 2 track whose ``at_switch`` end carries ``conn`` (the other an openEnd)."""
    ends = {"begin": ("trackBegin", "0"), "end": ("trackEnd", "100")}
    parts = []
    for side in ("begin", "end"):
        tag, pos = ends[side]
        inner = conn if side == at_switch else f'<openEnd id="{ident}_{side}_open"/>'
        parts.append(f'<{tag} id="{ident}_{side}" pos="{pos}">{inner}</{tag}>')
    return f'<track id="{ident}"><trackTopology>{"".join(parts)}{{switch_{ident}}}</trackTopology></track>'


MIRROR = {"left": "right", "right": "left"}


@pytest.mark.parametrize("holder", ["A", "B"])
@pytest.mark.parametrize("end_a", ["begin", "end"])
@pytest.mark.parametrize("end_b", ["begin", "end"])
@pytest.mark.parametrize("end_c", ["begin", "end"])
@pytest.mark.parametrize("side", ["left", "right"])
def test_one_switch_described_every_way_gives_one_row(
    holder: str, end_a: str, end_b: str, end_c: str, side: str, tmp_path: Path
) -> None:
    """Toe track A, through track B, branch C diverging to ``side`` seen from the toe —
    written with the switch on A or on B and each track in either direction (railML 2:
    ``@orientation`` and ``@course`` are seen in the direction of the switch's own track).
    Travelling A → B runs in A's direction when A's end is at the switch and in B's direction
    when B's begin is: then the branch is outgoing and its course is ``side``; otherwise
    incoming, course mirrored. Every description gives the same switch row."""
    ends = {"A": end_a, "B": end_b}
    along = ends[holder] == ("end" if holder == "A" else "begin")
    orientation, course = ("outgoing", side) if along else ("incoming", MIRROR[side])
    through = "B" if holder == "A" else "A"
    tracks = {
        "A": _track2("A", end_a, '<connection id="cA" ref="cB"/>'),
        "B": _track2("B", end_b, '<connection id="cB" ref="cA"/>'),
        "C": _track2("C", end_c, '<connection id="cC" ref="cS"/>'),
    }
    pos = "0" if ends[holder] == "begin" else "100"
    switch = (
        f'<connections><switch id="W" pos="{pos}"><connection id="cS" ref="cC" course="{course}" '
        f'orientation="{orientation}"/></switch></connections>'
    )
    body = "".join(t.replace(f"{{switch_{k}}}", switch if k == holder else "") for k, t in tracks.items())
    src = tmp_path / "w.railml"
    src.write_text(
        f'<railml xmlns="https://www.railml.org/schemas/2018" version="2.4"><infrastructure id="i">'
        f"<tracks>{body}</tracks></infrastructure></railml>",
        encoding="utf-8",
    )
    out = tmp_path / "o"
    import_railml(src, out)
    (sw,) = _rows(out, "switches")
    branches = {side: ("C", end_c), MIRROR[side]: ("B", end_b)}
    assert (sw["a1_track"], sw["a1_end"]) == ("A", end_a), (holder, through)
    assert (sw["b1_track"], sw["b1_end"]) == branches["left"]
    assert (sw["b2_track"], sw["b2_end"]) == branches["right"]
    assert sw["diverging_side"] == side
    assert _links(out) == {
        _link("A", end_a, "B", end_b, "both", "W"),
        _link("A", end_a, "C", end_c, "both", "W"),
        _link("B", end_b, "C", end_c, "none", "W"),
    }
