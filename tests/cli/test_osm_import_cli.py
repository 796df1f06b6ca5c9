"""``db import`` of OSM through the CLI, and the user guide's workflow run as written
(docs/howto/import-osm.md: db import → db build → db validate on the VDE 8.2 file)."""

from __future__ import annotations

import json
import os
import re
import shlex
from collections import Counter
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "howto" / "import-osm.md"
runner = CliRunner()


def _commands() -> list[list[str]]:
    block = re.search(r"## Workflow\n\n```sh\n(.*?)```", GUIDE.read_text(encoding="utf-8"), re.S)
    assert block is not None
    return [shlex.split(line)[1:] for line in block.group(1).splitlines() if line.startswith("trainpos ")]


def test_the_guide_workflow_runs_on_the_vde_file(tmp_path: Path) -> None:
    """The guide's commands as written; ``db validate`` says what the guide says it says
    (section "What db validate reports on the VDE 8.2 file": exit 1, 10 switch_overlap
    errors, 169 + 4 + 2 warnings)."""
    cmds = _commands()
    assert [c[:2] for c in cmds] == [["db", "import"], ["db", "build"], ["db", "validate"]]
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        (tmp_path / "tests").symlink_to(ROOT / "tests")
        outputs = []
        for cmd, code in zip(cmds, (0, 0, 1), strict=True):
            res = runner.invoke(app, cmd)
            assert res.exit_code == code, (cmd, res.output)
            outputs.append(res.output)
        res = runner.invoke(app, [*cmds[2], "--format", "json"])
    finally:
        os.chdir(cwd)
    report = json.loads((tmp_path / "vde-src" / "import_report.json").read_text())
    assert report["rows"]["switches"] == 811 and (tmp_path / "vde.sqlite").is_file()
    assert "10 error(s), 175 warning(s)" in outputs[2]
    counts = Counter((f["severity"], f["rule"]) for f in json.loads(res.output)["findings"])
    assert counts == {
        ("error", "topology.switch_overlap"): 10,
        ("warning", "topology.open_end"): 169,
        ("warning", "topology.isolated_track"): 4,
        ("warning", "schema.empty_table"): 2,
    }
    guide = GUIDE.read_text(encoding="utf-8")
    for (severity, rule), n in counts.items():
        assert f"| `{rule}` ({severity}) | {n} |" in guide


def test_the_format_is_taken_from_the_file_name(tmp_path: Path) -> None:
    res = runner.invoke(app, ["db", "import", str(ROOT / "tests/data/osm/junction.osm"), "--out", str(tmp_path / "j")])
    assert res.exit_code == 0, res.output
    assert "Imported (OSM)" in res.output and (tmp_path / "j" / "switches.csv").is_file()
    again = runner.invoke(
        app, ["db", "import", str(ROOT / "tests/data/osm/junction.osm"), "--out", str(tmp_path / "j")]
    )
    assert again.exit_code == 3


def test_a_bzip2_osm_file_reads_the_same(tmp_path: Path) -> None:
    import bz2

    src = ROOT / "tests/data/osm/junction.osm"
    packed = tmp_path / "junction.osm.bz2"
    packed.write_bytes(bz2.compress(src.read_bytes()))
    for name, path in (("plain", src), ("bz2", packed)):
        res = runner.invoke(app, ["db", "import", str(path), "--out", str(tmp_path / name)])
        assert res.exit_code == 0, res.output
    for table in ("tracks", "connections", "switches", "track_points"):
        assert (tmp_path / "plain" / f"{table}.csv").read_text() == (tmp_path / "bz2" / f"{table}.csv").read_text()


@pytest.mark.parametrize(("railways", "code"), [("tram", 0), ("subway", 1), (" , ", 2)])
def test_osm_railway_chooses_the_ways(tmp_path: Path, railways: str, code: int) -> None:
    res = runner.invoke(
        app,
        [
            "db",
            "import",
            str(ROOT / "tests/data/osm/junction.osm"),
            "--format",
            "osm",
            "--out",
            str(tmp_path / "o"),
            "--osm-railway",
            railways,
        ],
    )
    assert res.exit_code == code, res.output
