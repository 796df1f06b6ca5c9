"""railML ids from DB ids (:mod:`dbtools.interchange.railml_ids`): always an XML NCName,
injective; the export of a DB with awkward ids (digit first, spaces, colons, underscores,
Japanese) validates with xs:ID and its ids come back exactly through the designators, also
with our extension attributes stripped."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from lxml import etree

from dbtools.build import build_db
from dbtools.diff import diff_paths
from dbtools.interchange.export import ExportFormat, export_network
from dbtools.interchange.importer import import_railml
from dbtools.interchange.model import RailmlDoc
from dbtools.interchange.railml_ids import REGISTER, escape, unescape, xml_id
from dbtools.interchange.xmltree import TPOS_NS
from dbtools.interchange.xsd import load_schema

XSD = Path(__file__).resolve().parents[2] / "data" / "railml" / "railml3-subset.xsd"
R = "{https://www.railml.org/schemas/3.2}"

# XML 1.0 (5th ed.) NCName, written out from the spec's NameStartChar / NameChar minus ':'
_START = (
    "A-Z_a-z\u00c0-\u00d6\u00d8-\u00f6\u00f8-\u02ff\u0370-\u037d\u037f-\u1fff\u200c-\u200d"
    "\u2070-\u218f\u2c00-\u2fef\u3001-\ud7ff\uf900-\ufdcf\ufdf0-\ufffd\U00010000-\U000effff"
)
NCNAME = re.compile(f"[{_START}][{_START}\\-.0-9\u00b7\u0300-\u036f\u203f-\u2040]*")
ASCII_NCNAME = re.compile(r"[A-Za-z_][A-Za-z0-9._-]*")

DB_IDS = st.text(
    alphabet=st.one_of(
        st.sampled_from("0123456789 :_-.・駅東京曲線　/#\t"),
        st.characters(codec="utf-8", exclude_categories=("Cs",)),
    ),
    max_size=12,
)


@pytest.mark.parametrize(
    ("kind", "parts", "expected"),
    [
        ("bal", ("0420-01-U-I1",), "bal_0420-01-U-I1"),
        ("bg", ("0420", "01", "U"), "bg_0420_01_U"),
        ("bal", ("a b",), "bal_a.20.b"),
        ("bal", ("x:y",), "bal_x.3A.y"),
        ("bal", ("a_b",), "bal_a.5F.b"),
        ("bal", ("a.b",), "bal_a.2E.b"),
        ("hc", ("駅",), "hc_.99C5."),
        ("sl", ("",), "sl_"),
        ("co", (), "co"),
    ],
)
def test_xml_id_by_hand(kind: str, parts: tuple[str, ...], expected: str) -> None:
    assert xml_id(kind, *parts) == expected
    assert NCNAME.fullmatch(expected) and ASCII_NCNAME.fullmatch(expected)


def test_xml_id_kind_must_be_a_word() -> None:
    with pytest.raises(ValueError, match="not an ASCII word"):
        xml_id("1x", "a")


@given(st.lists(DB_IDS, min_size=1, max_size=40, unique=True))
def test_xml_id_is_an_ncname_and_injective(ids: list[str]) -> None:
    out = [xml_id("bal", i) for i in ids]
    assert all(NCNAME.fullmatch(o) and ASCII_NCNAME.fullmatch(o) for o in out)
    assert len(set(out)) == len(ids)
    assert [unescape(escape(i)) for i in ids] == ids


@given(st.lists(st.tuples(st.sampled_from(["bg", "hc", "tr"]), st.lists(DB_IDS, max_size=4)), max_size=30))
def test_xml_id_over_kinds_and_parts_is_injective(keys: list[tuple[str, list[str]]]) -> None:
    """Distinct (kind, parts) never share an id: ids are unique across the whole document."""
    unique = {(k, tuple(p)) for k, p in keys}
    out = {xml_id(k, *p) for k, p in unique}
    assert len(out) == len(unique) and all(NCNAME.fullmatch(o) for o in out)


# ---------------------------------------------------------------------------- the export


def _awkward(i: int, old: str) -> str:
    return ["0 駅:東京 ", "a_b", "a.5F.b", "x y:z", "曲線 1"][i % 5] + f"{i}" + old


@pytest.fixture(scope="module")
def awkward_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from dbtools.sample_network import sample_source_dir

    d = tmp_path_factory.mktemp("awkward")
    src = d / "src"
    shutil.copytree(sample_source_dir(), src)
    b = pd.read_csv(src / "balises.csv", dtype=str, keep_default_na=False)
    b["balise_id"] = [_awkward(i, v) for i, v in enumerate(b["balise_id"])]
    b.to_csv(src / "balises.csv", index=False)
    fp = pd.read_csv(src / "feature_points.csv", dtype=str, keep_default_na=False)
    fp["feature_id"] = "曲線 " + fp["feature_id"] + ":1"
    fp.to_csv(src / "feature_points.csv", index=False)
    db = d / "awkward.sqlite"
    build_db(src, db, db_version="awkward")
    return db


def test_awkward_ids_validate_and_round_trip(awkward_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "net.railml"
    export_network(awkward_db, out, ExportFormat.railml)
    tree = etree.parse(str(out))
    assert load_schema(XSD).validate(tree), load_schema(XSD).error_log
    root = tree.getroot()
    ids = [e.get("id") for e in root.iter() if e.get("id")]
    assert len(ids) == len(set(ids)) and all(ASCII_NCNAME.fullmatch(i) for i in ids)
    from dbtools.database import read_network

    db_ids = set(read_network(awkward_db).balises["balise_id"])
    entries = {d.getparent().get("id"): d.get("entry") for d in root.iter(f"{R}designator")}
    bal = {e.get("id") for e in root.iter(f"{R}balise")}
    assert {entries[i] for i in bal} == db_ids and all(
        d.get("register") == REGISTER for d in root.iter(f"{R}designator")
    )
    src = tmp_path / "src"
    r = import_railml(out, src)
    assert not [f for f in r.findings if f.rule == "railml.unmapped"], [str(f) for f in r.findings]
    build_db(src, tmp_path / "back.sqlite", db_version="back")
    d = diff_paths(awkward_db, tmp_path / "back.sqlite")
    assert not d.has_changes and d.old["content_hash"] == d.new["content_hash"], d.summary


def test_awkward_ids_come_back_without_our_extensions(awkward_db: Path, tmp_path: Path) -> None:
    """A plain railML consumer's view: no tpos attribute at all, the ids from the designators."""
    out = tmp_path / "net.railml"
    export_network(awkward_db, out, ExportFormat.railml)
    tree = etree.parse(str(out))
    for el in tree.getroot().iter():
        for k in [k for k in el.attrib if k.startswith("{" + TPOS_NS) and not k.endswith(("}lineCode", "}track"))]:
            del el.attrib[k]
    tree.write(str(tmp_path / "plain.railml"))
    pairs = "".join(f'"bg_0420_{s:02d}_{t}" = "{s:02d}"\n' for s in range(1, 7) for t in "UD")
    (tmp_path / "map.toml").write_text("[initial_pairs]\n" + pairs, encoding="utf-8")
    src = tmp_path / "src"
    import_railml(tmp_path / "plain.railml", src, line_map=tmp_path / "map.toml")
    from dbtools.database import read_network

    net = read_network(awkward_db)
    back = pd.read_csv(src / "balises.csv", dtype=str)
    assert set(back["balise_id"]) == set(net.balises["balise_id"])
    fp = pd.read_csv(src / "feature_points.csv", dtype=str)
    assert set(fp["feature_id"]) == set(net.feature_points["feature_id"])


def _read(tmp_path: Path, body: str) -> RailmlDoc:
    from dbtools.interchange import railml3
    from dbtools.interchange import xmltree as xt
    from tests.dbtools.interchange.railml_samples import railml3 as doc

    p = tmp_path / "d.railml"
    p.write_text(doc(body), encoding="utf-8")
    return railml3.read(xt.parse(p), str(p), "3.2")


def _balise(ident: str, t: float, *designators: tuple[str, str]) -> str:
    ds = "".join(f'<designator register="{reg}" entry="{e}"/>' for reg, e in designators)
    return f'<balise id="{ident}">{ds}<spotLocation id="sl{t}" netElementRef="ne1" intrinsicCoord="{t}"/></balise>'


def test_importer_prefers_our_designator_and_falls_back_to_the_id(tmp_path: Path) -> None:
    body = _balise("bal_x", 0.2, ("other", "theirs"), (REGISTER, "0420 駅:1")) + _balise("plain", 0.4, ("RINF", "r"))
    doc = _read(tmp_path, body)
    assert [b.id for b in doc.balises] == ["0420 駅:1", "plain"] and not doc.findings
    assert all(doc.is_used(d) for d in doc.root.iter(f"{R}designator"))


def test_duplicate_designator_entry_is_a_duplicate_id(tmp_path: Path) -> None:
    body = _balise("a", 0.2, (REGISTER, "b1")) + _balise("b", 0.4, (REGISTER, "b1")) + _balise("b1", 0.6)
    doc = _read(tmp_path, body)
    assert [b.id for b in doc.balises] == ["b1"]
    dup = [f for f in doc.findings if f.rule == "railml.duplicate_id"]
    assert len(dup) == 2 and all("'b1'" in f.message and "first at line" in f.message for f in dup)
    assert [f.keys["id"] for f in dup] == ["b", "b1"]
