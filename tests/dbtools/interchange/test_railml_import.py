"""``db import --format railml``: the real Finnish railML 2.2 file, hand-computed railML 2.4
mileage/curve/balise cases, railML 3 via our own export without extensions, bad input."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.interchange.importer import import_railml
from schemas.errors import FindingsError, InputError, RefusedError
from tests.dbtools.interchange.railml_samples import MAP24, RAILML24, balise3, lon_at, railml3

DATA = Path(__file__).resolve().parents[2] / "data" / "railml"
FINLAND = DATA / "Track-007_28-47.railml.xml"


def _write(tmp: Path, name: str, text: str) -> Path:
    p = tmp / name
    p.write_text(text, encoding="utf-8")
    return p


def test_finnish_file_accounts_for_every_balise(tmp_path: Path) -> None:
    out = tmp_path / "fi"
    r = import_railml(FINLAND, out)
    assert r.version == "2.2" and r.balises_seen == 76
    ids = set(re.findall(r'<balise id="([^"]+)"', FINLAND.read_text(encoding="utf-8")))
    assert len(ids) == 76
    written = pd.read_csv(out / "balises.csv", dtype=str)
    # no initial pair in the file (nor a map): its balises are balise groups, all written as G
    # rows (test_railml_topology has the groups); each group says it has no ETCS identity
    assert set(written["balise_id"]) == ids and set(written["kind"]) == {"G"}
    assert not [f for f in r.findings if f.rule == "railml.no_pair"]
    assert sum(f.rule == "railml.balise_identity" for f in r.findings) == 45
    signals = [f for f in r.findings if f.rule == "railml.unmapped" and f.message.startswith("signal ")]
    assert len(signals) == 34 and all(
        f.row and f.keys["element"].startswith("/railml/infrastructure/tracks") for f in signals
    )
    # the generator's quirks are reported, not fatal
    assert sum(f.rule == "railml.quirk" for f in r.findings) == 19 + 1  # 19 trackRef, 1 connection
    assert any(f.rule == "railml.position" and "placed by its @absPos 41097" in f.message for f in r.findings)
    report = json.loads((out / "import_report.json").read_text(encoding="utf-8"))
    assert report["balise_names"]["x.x.xxx.LIVI.INFRA.11.1188587"] == "18511"
    lines = pd.read_csv(out / "lines.csv", dtype=str)
    assert lines.to_dict("records") == [{"line_code": "line_007_28_47", "name": "007 28-47"}]
    assert (out / "gis.csv").read_text(encoding="utf-8").strip() == "line_code,track,km_m,lat,lon,height_m"


def test_finnish_file_with_a_map_gives_c_balises(tmp_path: Path) -> None:
    # illustrative only: the Finnish data name no initial pairs; here the group at km 34315
    # (balises 18770/18772, read "down") is declared one to show the C mapping downstream
    m = _write(
        tmp_path,
        "fi.toml",
        'metric_crs = "EPSG:3067"\n[lines.line_007_28_47]\nline_code = "007"\ntrack = "S"\n'
        '[initial_pairs]\n"x.x.xxx.LIVI.INFRA.11.1211144" = "KV"\n',
    )
    out = tmp_path / "fi"
    r = import_railml(FINLAND, out, line_map=m)
    b = pd.read_csv(out / "balises.csv", dtype=str)
    pair = b[b["kind"].isin(["I1", "I2"])]
    assert sorted(pair["balise_id"]) == ["x.x.xxx.LIVI.INFRA.11.1211144", "x.x.xxx.LIVI.INFRA.11.1211155"]
    c = b[b["kind"] == "C"]
    assert len(c) > 0 and set(c["station_code"]) == {"KV"} and set(c["line_code"]) == {"007"}
    assert (c["km_actual_m"].astype(float) > 34315).all()  # S runs km-increasing: after the pair
    first = c.sort_values("km_actual_m", key=lambda s: s.astype(float)).iloc[0]
    assert float(first["dist_from_initial_m"]) == pytest.approx(float(first["km_actual_m"]) - 34315, abs=1e-6)
    assert 'metric_crs = "EPSG:3067"' in (out / "network.toml").read_text(encoding="utf-8")
    assert r.rows["balises"] == len(b)


def test_railml24_mileage_change_curve_and_balises(tmp_path: Path) -> None:
    src = _write(tmp_path, "t.railml", RAILML24)
    m = _write(tmp_path, "map.toml", MAP24)
    out = tmp_path / "src"
    r = import_railml(src, out, line_map=m)
    b = pd.read_csv(out / "balises.csv", dtype={"line_code": str, "station_code": str}).set_index("balise_id")
    # pos → km through the mileage change: 1000 + pos before pos 1500, 2600 + (pos − 1500) after
    assert b.loc["b_i1", "km_actual_m"] == 2100 and b.loc["b_i2", "km_actual_m"] == 2105
    assert b.loc["b_i1", "kind"] == "I1" and b.loc["b_i2", "kind"] == "I2" and b.loc["b_i1", "station_code"] == "05"
    assert b.loc["b_c", "km_actual_m"] == 2900 and b.loc["b_c", "kind"] == "C"
    assert b.loc["b_c", "signal_type"] == "home"  # the home signal 50 m ahead
    assert b.loc["b_c", "dist_from_initial_m"] == 700  # travelled, not the km difference (800)
    # a stated absPos is kept; the pos-derived km (4000) differs by 5 m: reported
    assert b.loc["b_lone", "km_actual_m"] == 4005 and b.loc["b_lone", "station_code"] == "05"
    assert any(f.rule == "railml.mileage" and "+5.0 m" in f.message for f in r.findings)
    # the curve: TS km 1400, L1 = L2 = 60 m, ST km 1760 → rows at the lower-limit crossings
    fp = pd.read_csv(out / "feature_points.csv", dtype={"line_code": str})
    assert fp["km_m"].tolist() == [1380.0, 1400.0, 1448.0, 1712.0, 1760.0, 1780.0]
    assert fp["attribute"].tolist() == ["straight", "transition", "left", "transition", "straight", "none"]
    assert fp["radius_m"].tolist() == [0, 0, 600, 0, 0, 0] and set(fp["feature_id"]) == {"rc2"}
    # geometry → survey → 20 m grid with the break 2500 → 2600
    gis = pd.read_csv(out / "gis.csv", dtype={"line_code": str})
    assert len(gis) == 76 + 76 and gis["km_m"].min() == 1000 and gis["km_m"].max() == 4100
    kb = pd.read_csv(out / "km_breaks.csv", dtype={"line_code": str})
    assert kb[["km_from_m", "km_to_m"]].values.tolist() == [[2500.0, 2600.0]]
    p = gis.set_index("km_m").loc[2620.0]
    assert abs(p["lon"] - lon_at(1520)) * 55_660 < 1.0 and abs(p["lat"] - 60.0) < 1e-6
    assert (out / "survey" / "centrelines.csv").is_file() and (out / "survey" / "kmposts.csv").is_file()
    unmapped = {f.keys.get("id") for f in r.findings if f.rule == "railml.unmapped"}
    assert {"sig1", "sc1"} <= unmapped
    lines = pd.read_csv(out / "lines.csv", dtype=str)
    assert lines.to_dict("records") == [{"line_code": "9001", "name": "Test line (mapped)"}]
    build_db(out, tmp_path / "t.sqlite", db_version="t")  # the folder is a source set


def test_railml3_without_our_extensions_derives_features_and_grid(sample_db: Path, tmp_path: Path) -> None:
    from lxml import etree

    from dbtools.interchange.export import ExportFormat, export_network
    from dbtools.interchange.xmltree import TPOS_NS

    export_network(sample_db, tmp_path / "net.railml", ExportFormat.railml)
    tree = etree.parse(str(tmp_path / "net.railml"))
    for el in tree.getroot().iter():
        for k in [k for k in el.attrib if k.startswith("{" + TPOS_NS) and not k.endswith(("}lineCode", "}track"))]:
            del el.attrib[k]
    tree.write(str(tmp_path / "plain.railml"))
    pairs = "".join(f'"bg_0420_{s:02d}_{t}" = "{s:02d}"\n' for s in range(1, 7) for t in "UD")
    m = _write(tmp_path, "map.toml", "[initial_pairs]\n" + pairs)
    out = tmp_path / "src"
    import_railml(tmp_path / "plain.railml", out, line_map=m)
    from dbtools.sample_network import sample_source_dir

    key = ["line_code", "track", "feature_id", "seq"]
    a = pd.read_csv(sample_source_dir() / "feature_points.csv", dtype={"line_code": str}).set_index(key).sort_index()
    b = pd.read_csv(out / "feature_points.csv", dtype={"line_code": str}).set_index(key).sort_index()
    assert a.index.equals(b.index)
    assert (a["km_m"] - b["km_m"]).abs().max() < 1e-6 and (a["radius_m"] == b["radius_m"]).all()
    assert (a["attribute"] == b["attribute"]).all()
    ga = pd.read_csv(sample_source_dir() / "gis.csv", dtype={"line_code": str}).set_index(
        ["line_code", "track", "km_m"]
    )
    gb = pd.read_csv(out / "gis.csv", dtype={"line_code": str}).set_index(["line_code", "track", "km_m"])
    j = ga.join(gb, how="inner", suffixes=("", "_n"))
    assert len(j) == len(ga) == len(gb)
    assert ((j["lat"] - j["lat_n"]).abs().max() * 111_000) < 0.5  # the grid from gis grid, not copied
    ba = pd.read_csv(sample_source_dir() / "balises.csv", dtype=str).set_index("balise_id")
    bb = pd.read_csv(out / "balises.csv", dtype=str).set_index("balise_id")
    assert ba.index.sort_values().equals(bb.index.sort_values())
    assert (ba["kind"] == bb.loc[ba.index, "kind"]).all()
    assert (ba["station_code"] == bb.loc[ba.index, "station_code"]).all()
    assert (
        ba["dist_from_initial_m"].astype(float).fillna(-1)
        - bb.loc[ba.index, "dist_from_initial_m"].astype(float).fillna(-1)
    ).abs().max() < 1e-6


def test_railml3_gml_line_only_gives_a_grid(sample_db: Path, tmp_path: Path) -> None:
    """Without geometric coordinates the tracks' gml LineStrings are the centrelines; their
    vertices get km from the netElement's mileage, and the grid follows the same line."""
    from lxml import etree

    from dbtools.interchange.export import ExportFormat, export_network

    export_network(sample_db, tmp_path / "net.railml", ExportFormat.railml)
    tree = etree.parse(str(tmp_path / "net.railml"))
    for el in list(tree.getroot().iter("{*}geometricCoordinate")):
        el.getparent().remove(el)
    tree.getroot().attrib.pop("{urn:x-trainpos:railml:1}gisGrid")
    tree.write(str(tmp_path / "gml.railml"))
    out = tmp_path / "src"
    import_railml(tmp_path / "gml.railml", out)
    from dbtools.sample_network import sample_source_dir

    ga = pd.read_csv(sample_source_dir() / "gis.csv", dtype={"line_code": str}).set_index(
        ["line_code", "track", "km_m"]
    )
    gb = pd.read_csv(out / "gis.csv", dtype={"line_code": str}).set_index(["line_code", "track", "km_m"])
    j = ga.join(gb, how="inner", suffixes=("", "_n"))
    assert len(j) == len(ga) == len(gb)
    assert ((j["lat"] - j["lat_n"]).abs().max() * 111_000) < 0.5  # rebuilt through gis grid


# ---------------------------------------------------------------------------- bad input


def _errors(tmp: Path, text: str) -> list[str]:
    src = _write(tmp, "bad.railml", text)
    with pytest.raises(FindingsError) as ei:
        import_railml(src, tmp / "out")
    assert not (tmp / "out").exists()  # nothing written
    return [f"{f.rule}@{f.row}:{f.keys.get('element')}" for f in ei.value.findings if f.severity == "error"]


def test_malformed_xml_names_the_line(tmp_path: Path) -> None:
    src = _write(tmp_path, "bad.railml", RAILML24[:700])
    with pytest.raises(InputError) as ei:
        import_railml(src, tmp_path / "out")
    assert "malformed XML" in str(ei.value) and ei.value.row is not None and not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "doc",
    [
        '<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">]><railML '
        'version="3.2">&b;</railML>',
        '<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]><railML version="3.2"><x>&x;</x></railML>',
        '<!DOCTYPE railML SYSTEM "http://example.invalid/railml.dtd"><railML version="3.2"/>',
    ],
    ids=["entity-expansion", "external-entity", "external-dtd"],
)
def test_entities_and_external_dtds_are_refused(tmp_path: Path, doc: str) -> None:
    src = _write(tmp_path, "evil.railml", '<?xml version="1.0"?>' + doc)
    with pytest.raises(InputError, match="refused"):
        import_railml(src, tmp_path / "out")


def test_unknown_version(tmp_path: Path) -> None:
    errs = _errors(tmp_path, railml3(balise3("b1"), version="3.9"))
    assert errs == ["railml.version@2:/railML"]


def test_missing_ids_duplicates_undefined_tracks_and_units(tmp_path: Path) -> None:
    body = "\n".join([balise3(None), balise3("b1"), balise3("b1", t=0.6), balise3("b2", ne="ne_missing")])
    errs = _errors(tmp_path, railml3(body))
    assert any(e.startswith("railml.missing_id@") and e.endswith("/balises/balise[1]") for e in errs)
    assert any(e.startswith("railml.duplicate_id@") and e.endswith("/balises/balise[3]") for e in errs)
    assert any(e.startswith("railml.undefined_track@") and e.endswith("/balise[4]/spotLocation") for e in errs)
    units = _errors(tmp_path / "u", railml3(balise3("b1"), units="km")) if (tmp_path / "u").mkdir() is None else []
    assert any(e.startswith("railml.units@") for e in units)


def test_output_refused_without_force(tmp_path: Path) -> None:
    src = _write(tmp_path, "t.railml", RAILML24)
    out = tmp_path / "src"
    out.mkdir()
    (out / "keep.txt").write_text("x", encoding="utf-8")
    with pytest.raises(RefusedError):
        import_railml(src, out)
    # --force never replaces a folder trainpos did not write (dbtools/atomic.py's rule) …
    with pytest.raises(RefusedError, match="replaces only a folder trainpos wrote"):
        import_railml(src, out, force=True)
    assert (out / "keep.txt").read_text(encoding="utf-8") == "x"
    # … but replaces its own output
    mine = tmp_path / "mine"
    import_railml(src, mine)
    import_railml(src, mine, force=True)
    assert (mine / "balises.csv").is_file()
