"""``db export/import --format railml --xsd``: validation against a user-supplied XML Schema
(here the hand-written subset of railML 3.2 in tests/data/railml/railml3-subset.xsd): the
valid case writes, a schema error exits 1 with its line and the schema's reason and writes
nothing, an unreadable schema exits 2."""

from __future__ import annotations

from pathlib import Path

import pytest
from lxml import etree
from typer.testing import CliRunner

from cli.main import app
from dbtools.interchange.xsd import load_schema, schema_findings
from schemas.errors import InputError

DATA = Path(__file__).resolve().parents[2] / "data" / "railml"
XSD = DATA / "railml3-subset.xsd"
FINLAND = DATA / "Track-007_28-47.railml.xml"
DESIGNATOR = '<xs:element name="designator" type="rail3:tDesignator" minOccurs="0" maxOccurs="unbounded"/>'


def invoke(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "400"})


@pytest.fixture(scope="module")
def exported(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("xsd") / "net.railml"
    r = invoke("db", "export", sample_db, "--format", "railml", "--out", out, "--xsd", XSD)
    assert r.exit_code == 0, r.output
    return out


def _strict(tmp_path: Path) -> Path:
    """The subset with two designators every balise must have before its spotLocation (the
    export writes one, of our register)."""
    text = XSD.read_text(encoding="utf-8")
    assert DESIGNATOR in text
    strict = tmp_path / "strict.xsd"
    strict.write_text(text.replace(DESIGNATOR, DESIGNATOR.replace('minOccurs="0"', 'minOccurs="2"')), encoding="utf-8")
    return strict


def _first_line(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if needle in line)


def test_valid_export_is_written_and_valid(exported: Path) -> None:
    assert load_schema(XSD).validate(etree.parse(str(exported)))


def test_invalid_export_names_line_and_reason_and_writes_nothing(
    exported: Path, sample_db: Path, tmp_path: Path
) -> None:
    out = tmp_path / "strict.railml"
    r = invoke("db", "export", sample_db, "--format", "railml", "--out", out, "--xsd", _strict(tmp_path))
    assert r.exit_code == 1, r.output
    assert not out.exists() and not list(tmp_path.glob("*.railml*"))
    line = _first_line(exported, "<spotLocation")  # the export is the same document as the valid one
    assert f"{out}:{line}: the railML export is not valid against strict.xsd" in r.output
    assert "designator" in r.output and "31 schema error(s); nothing was written" in r.output
    assert "railml.xsd" in r.output  # one finding per schema error


def test_unreadable_schema_exits_2(sample_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "net.railml"
    r = invoke("db", "export", sample_db, "--format", "railml", "--out", out, "--xsd", tmp_path / "none.xsd")
    assert r.exit_code == 2 and "no such file" in r.output and not out.exists()
    broken = tmp_path / "broken.xsd"
    broken.write_text(XSD.read_text(encoding="utf-8")[:900], encoding="utf-8")
    r = invoke("db", "export", sample_db, "--format", "railml", "--out", out, "--xsd", broken)
    assert r.exit_code == 2 and "malformed XML" in r.output and f"{broken}:" in r.output and not out.exists()
    r = invoke("db", "export", sample_db, "--format", "railml", "--out", out, "--xsd", FINLAND)  # XML, no schema
    assert r.exit_code == 2 and "not a usable XML Schema" in r.output and not out.exists()
    r = invoke("db", "export", sample_db, "--format", "geojson", "--out", tmp_path / "n.geojson", "--xsd", XSD)
    assert r.exit_code == 2 and "--xsd validates railML only" in r.output


def test_import_validates_first(exported: Path, tmp_path: Path) -> None:
    r = invoke("db", "import", exported, "--format", "railml", "--out", tmp_path / "ok", "--xsd", XSD)
    assert r.exit_code == 0, r.output
    assert (tmp_path / "ok" / "balises.csv").is_file()
    bad = tmp_path / "bad.railml"
    text = exported.read_text(encoding="utf-8")
    bad.write_text(text.replace('applicationDirection="normal"', 'applicationDirection="sideways"', 1), "utf-8")
    line = _first_line(bad, "sideways")
    r = invoke("db", "import", bad, "--format", "railml", "--out", tmp_path / "bad", "--xsd", XSD)
    assert r.exit_code == 1, r.output
    assert f"{bad}:{line}: bad.railml is not valid against railml3-subset.xsd" in r.output
    assert "applicationDirection" in r.output and "sideways" in r.output and not (tmp_path / "bad").exists()
    r = invoke("db", "import", FINLAND, "--format", "railml", "--out", tmp_path / "fi", "--xsd", XSD)
    assert r.exit_code == 1 and "No matching global declaration" in r.output  # railML 2.2 is not 3.2
    assert not (tmp_path / "fi").exists()
    r = invoke("db", "import", exported, "--format", "railml", "--out", tmp_path / "x", "--xsd", tmp_path / "no.xsd")
    assert r.exit_code == 2 and not (tmp_path / "x").exists()


def test_findings_carry_element_path_and_line(tmp_path: Path) -> None:
    doc = tmp_path / "d.xml"
    doc.write_text(
        '<railML xmlns="https://www.railml.org/schemas/3.2" version="3.2">\n'
        '  <infrastructure id="is">\n'
        "    <topology><netElements>\n"
        '      <netElement id="n1" length="ten"/>\n'
        "    </netElements></topology>\n"
        "  </infrastructure>\n"
        "</railML>\n",
        encoding="utf-8",
    )
    (f,) = schema_findings(load_schema(XSD), etree.parse(str(doc)), file=str(doc), xsd=XSD)
    assert f.rule == "railml.xsd" and f.row == 4 and f.file == str(doc) and "'ten'" in f.message
    assert "netElement" in f.keys["element"]
    with pytest.raises(InputError):
        load_schema(tmp_path)  # a folder
