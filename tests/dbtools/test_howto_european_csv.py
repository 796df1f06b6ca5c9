"""docs/howto/european-csv.md stays runnable: every ``trainpos`` command of its ``sh`` blocks
runs, in order, in a scratch folder (paths under ``tests/data/`` point at the repository's),
with the exit code the page states; the warnings and content hashes it states are checked."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from tests.howto import page_commands

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "howto" / "european-csv.md"


def content_hash(db: Path) -> str:
    with sqlite3.connect(db) as con:
        return str(con.execute("SELECT value FROM meta WHERE key = 'content_hash'").fetchone()[0])


def test_the_page_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    calls = page_commands(PAGE)
    assert len(calls) == 6
    outputs = {}
    for argv in calls:
        r = CliRunner().invoke(app, argv, env={"COLUMNS": "300"})
        flat = " ".join(r.output.split())
        outputs[" ".join(argv[:3])] = flat
        if "--decimal" in argv and argv[argv.index("--decimal") + 1] == ".":  # the page's refusal
            assert r.exit_code == 2, (argv, r.output)
            assert "gis.csv:2, column 'lat': '35,905939253' has a decimal comma, but --decimal says" in flat
            continue
        assert r.exit_code == 0, (argv, r.output)
        assert "Traceback" not in r.output
    assert content_hash(tmp_path / "de.sqlite") == content_hash(tmp_path / "machine.sqlite")
    assert content_hash(tmp_path / "fi.sqlite") == content_hash(tmp_path / "machine.sqlite")
    de = next(v for k, v in outputs.items() if k.endswith("sources_de") and k.startswith("db build"))
    assert de.count("source.locale") == 4
    assert de.count("`;`-separated with decimal commas (UTF-8 with a byte-order mark)") >= 2
    assert "0 error(s), 4 warning(s)" in de
    fi = next(v for k, v in outputs.items() if k.endswith("sources_fi"))
    assert "source.locale" not in fi
    fr = next(v for k, v in outputs.items() if k.endswith("sources_fr"))
    assert "0 error(s), 0 warning(s)" in fr
    imported = pd.read_parquet(tmp_path / "run-de" / "imu.parquet")
    assert len(imported) == 50 and "source.locale" in outputs[next(k for k in outputs if k.startswith("logs import"))]
    r = CliRunner().invoke(
        app,
        [
            "logs", "import", str(ROOT / "tests/data/recorders/imu.csv"),
            "--mapping", str(ROOT / "tests/data/recorders/imu_mapping.toml"),
            "--vehicle", str(ROOT / "tests/data/recorders/vehicle.toml"), "--out", str(tmp_path / "run-m"),
        ],
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    pd.testing.assert_frame_equal(imported, pd.read_parquet(tmp_path / "run-m" / "imu.parquet"))
