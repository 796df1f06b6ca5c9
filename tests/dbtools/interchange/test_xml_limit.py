"""A railML file larger than ``[input] max_xml_mb`` is refused before it is parsed (issue 32
item 7: a 243 MB file took 6.4 GB and was killed): exit 2, naming the file and the setting."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from cli.main import app

DATA = Path(__file__).resolve().parents[2] / "data" / "railml"


def test_an_xml_file_over_the_limit_is_refused_before_parsing(tmp_path: Path) -> None:
    src = DATA / "Track-007_28-47.railml.xml"
    cfg = tmp_path / "small.toml"
    cfg.write_text("[input]\nmax_xml_mb = 0.01\n", encoding="utf-8")  # 10 KB; the file is 44 KB
    r = CliRunner().invoke(
        app, ["db", "import", str(src), "--format", "railml", "--out", str(tmp_path / "out"), "--config", str(cfg)]
    )
    assert r.exit_code == 2, r.output
    text = r.output.replace("\n", " ")
    assert "max_xml_mb" in text and "Track-007_28-47.railml.xml" in text
    assert not (tmp_path / "out").exists()


def test_within_the_limit_it_is_read(tmp_path: Path) -> None:
    src = DATA / "Track-007_28-47.railml.xml"
    r = CliRunner().invoke(app, ["db", "import", str(src), "--format", "railml", "--out", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
