"""The user guide's ``logs import`` examples (docs/guide/field-logs.md) on the repository's
hand-made files run as written."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app

ROOT = Path(__file__).resolve().parents[3]


def _examples() -> list[list[str]]:
    text = (ROOT / "docs" / "guide" / "field-logs.md").read_text(encoding="utf-8").replace("\\\n", " ")
    return [shlex.split(m)[1:] for m in re.findall(r"^trainpos logs import tests/data/recorders/.*$", text, re.M)]


def test_readme_import_examples_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    examples = _examples()
    assert len(examples) == 4  # NMEA, RINEX, UBX, CSV (the simulated UBX one needs a DB first)
    monkeypatch.chdir(ROOT)
    for k, argv in enumerate(examples):
        out = argv.index("--out") + 1
        argv[out] = str(tmp_path / f"run{k}")
        res = CliRunner().invoke(app, argv)
        assert res.exit_code == 0, (argv, res.output)
        assert (tmp_path / f"run{k}" / "run.json").is_file()
