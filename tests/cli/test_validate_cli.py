"""``trainpos db validate`` through the CLI: exit codes, --strict, JSON shape, unreadable and
tampered DBs, and randomly damaged source sets (never a traceback)."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pandas as pd
import pytest
from click.testing import Result
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.gis.geometry import Projector
from dbtools.sources import write_source_set
from fieldlogs.simulate.networks.synthetic import build_network, demo_line

FINDING_KEYS = {"rule", "severity", "table", "keys", "value", "limit", "message"}


def _run(args: list[str]) -> Result:
    """Invoke with a wide terminal so that Rich does not wrap file names."""
    return CliRunner().invoke(app, args, env={"COLUMNS": "400"})


def _no_traceback(result: Result) -> None:
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output
    assert result.exit_code != 4, result.output  # internal error


@pytest.fixture(scope="module")
def sources(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A clean 5 km double-track source set: 502 GIS points, 12 balises, 6 features."""
    net = build_network([demo_line(length_m=5000.0)], Projector(9))
    return write_source_set(net, tmp_path_factory.mktemp("v") / "src")


@pytest.fixture(scope="module")
def clean_db(sources: Path) -> Path:
    out = sources.parent / "clean.sqlite"
    build_db(sources, out, db_version="1")
    return out


def _edit_csv(src: Path, dst: Path, name: str, edit: dict[tuple[str, str], object]) -> Path:
    """Copy a source set, changing cells (balise_id or row number, column) of one file."""
    shutil.copytree(src, dst)
    frame = pd.read_csv(dst / f"{name}.csv", dtype=str, keep_default_na=False)
    for (key, col), value in edit.items():
        mask = frame.iloc[:, 0] == key
        frame.loc[mask, col] = str(value)
    frame.to_csv(dst / f"{name}.csv", index=False)
    return dst


def _json(result: Result) -> dict[str, object]:
    report = json.loads(result.stdout)
    assert set(report) == {"ok", "findings"}
    for f in report["findings"]:
        assert FINDING_KEYS <= set(f) <= FINDING_KEYS | {"file", "row", "column"}
    return report


def test_help_has_an_example() -> None:
    result = _run(["db", "validate", "--help"])
    assert result.exit_code == 0 and "Example: trainpos db validate" in result.stdout


def test_clean_db_and_sources_exit_0(clean_db: Path, sources: Path) -> None:
    for target in (clean_db, sources):
        result = _run(["db", "validate", str(target), "--format", "json"])
        assert result.exit_code == 0, result.output
        assert _json(result) == {"ok": True, "findings": []}
        table = _run(["db", "validate", str(target)])
        assert table.exit_code == 0 and "0 error(s), 0 warning(s)" in table.stdout


def test_errors_exit_1_with_json_findings(sources: Path, tmp_path: Path) -> None:
    src = _edit_csv(sources, tmp_path / "src", "balises", {("0900-02-U-I2", "km_actual_m"): 4742.0})
    build_db(src, tmp_path / "bad.sqlite")
    for target, where in ((tmp_path / "bad.sqlite", None), (src, src / "balises.csv")):
        result = _run(["db", "validate", str(target), "--format", "json"])
        assert result.exit_code == 1
        report = _json(result)
        assert report["ok"] is False
        (f,) = report["findings"]
        assert f["rule"] == "balise.pair_spacing" and f["severity"] == "error"
        assert f["keys"] == {"line_code": "0900", "station_code": "02", "track": "U"}
        assert f["value"] == 8.0 and f["limit"] == [4.5, 5.5]
        if where is None:
            assert "file" not in f and "row" not in f
        else:  # the I2 of pair 02 U is data row 8 of the file (line 9)
            assert f["file"] == str(where) and f["row"] == 9
    table = _run(["db", "validate", str(src)])
    assert table.exit_code == 1
    assert "balise.pair_spacing" in table.stdout and f"{src / 'balises.csv'}:9" in table.stdout
    assert "1 error(s), 0 warning(s)" in table.stdout


def test_strict_fails_on_warnings(sources: Path, tmp_path: Path) -> None:
    src = _edit_csv(sources, tmp_path / "src", "balises", {("0900-D-C001", "dist_from_initial_m"): 1755.0})
    lenient = _run(["db", "validate", str(src), "--format", "json"])
    assert lenient.exit_code == 0
    report = _json(lenient)
    assert report["ok"] is True and [f["rule"] for f in report["findings"]] == ["balise.dist_from_initial"]
    strict = _run(["db", "validate", str(src), "--format", "json", "--strict"])
    assert strict.exit_code == 1 and _json(strict)["ok"] is False
    assert _run(["db", "validate", str(src), "--strict"]).exit_code == 1


@pytest.mark.parametrize(
    ("damage", "needle"),
    [
        ("text", "not an SQLite database"),
        ("short", "truncated SQLite file"),
        ("missing_table", "table 'feature_points' is missing"),
        ("no_file", "no such file"),
    ],
)
def test_unreadable_db_exits_2(clean_db: Path, tmp_path: Path, damage: str, needle: str) -> None:
    target = tmp_path / "x.sqlite"
    if damage == "text":
        target.write_text("line_code,track\n")
    elif damage == "short":
        target.write_bytes(clean_db.read_bytes()[:60])
    elif damage == "missing_table":
        shutil.copy(clean_db, target)
        with sqlite3.connect(target) as conn:
            conn.execute("DROP TABLE feature_points")
        conn.close()
    result = _run(["db", "validate", str(target)])
    assert result.exit_code == 2
    _no_traceback(result)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], result.stderr


@pytest.mark.parametrize("where", [0.25, 0.5, 0.75, 0.99])
def test_corrupted_db_is_reported_not_crashed(clean_db: Path, tmp_path: Path, where: float) -> None:
    """A whole page in the middle overwritten (bytes in a page's free space would be harmless)."""
    data = bytearray(clean_db.read_bytes())
    page = int.from_bytes(data[16:18], "big")
    start = int(len(data) // page * where) * page
    data[start : start + page] = bytes(range(256)) * (page // 256)
    target = tmp_path / "corrupt.sqlite"
    target.write_bytes(bytes(data))
    result = _run(["db", "validate", str(target), "--format", "json"])
    _no_traceback(result)
    assert result.exit_code in (1, 2), result.output
    if result.exit_code == 2:
        assert result.stderr.startswith("error: ") and str(target) in result.stderr
    else:
        rules = {f["rule"] for f in _json(result)["findings"]}
        assert rules & {"db.integrity", "db.content_hash", "db.foreign_key"}, rules


def test_hand_edited_db_fails_content_hash(clean_db: Path, tmp_path: Path) -> None:
    target = tmp_path / "edited.sqlite"
    shutil.copy(clean_db, target)
    with sqlite3.connect(target) as conn:
        conn.execute("UPDATE balises SET km_equipment_m = km_equipment_m + 1 WHERE balise_id = '0900-D-C001'")
    conn.close()
    result = _run(["db", "validate", str(target), "--format", "json"])
    assert result.exit_code == 1
    (f,) = _json(result)["findings"]
    assert f["rule"] == "db.content_hash" and f["table"] == "meta"


# ----------------------------------------------------------------------------- damaged sources

FILES = ("gis", "balises", "feature_points")
NUMERIC = {
    "gis": ["km_m", "lat", "lon"],
    "balises": ["km_actual_m", "dist_from_initial_m"],
    "feature_points": ["km_m", "radius_m"],
}


@st.composite
def damages(draw: st.DrawFn) -> list[tuple[str, str, int, int, str]]:
    """1–3 damages: (file, operation, row seed, column seed, text)."""
    ops = st.sampled_from(["drop_column", "rename_column", "blank_cell", "text_in_number", "duplicate_row", "shuffle"])
    one = st.tuples(
        st.sampled_from(FILES),
        ops,
        st.integers(0, 10_000),
        st.integers(0, 100),
        st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs", "Cc")), min_size=1, max_size=8),
    )
    return draw(st.lists(one, min_size=1, max_size=3))


def _damage(src: Path, dst: Path, plan: list[tuple[str, str, int, int, str]]) -> set[str]:
    shutil.copytree(src, dst)
    touched = set()
    for name, op, r, c, text in plan:
        path = dst / f"{name}.csv"
        frame = pd.read_csv(path, dtype=str, keep_default_na=False)
        if frame.empty or not len(frame.columns):
            continue
        col = frame.columns[c % len(frame.columns)]
        i = r % len(frame)
        if op == "drop_column":
            frame = frame.drop(columns=[col])
        elif op == "rename_column":
            frame = frame.rename(columns={col: f"{col}_{text}".replace(",", ";").replace("\n", " ")})
        elif op == "blank_cell":
            frame.loc[i, col] = ""
        elif op == "text_in_number":
            numeric = [n for n in NUMERIC[name] if n in frame.columns]
            if numeric:
                frame.loc[i, numeric[c % len(numeric)]] = text
        elif op == "duplicate_row":
            frame = pd.concat([frame, frame.iloc[[i]]], ignore_index=True)
        else:
            frame = frame.sample(frac=1.0, random_state=r).reset_index(drop=True)
        frame.to_csv(path, index=False)
        touched.add(f"{name}.csv")
    return touched


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(plan=damages())
def test_damaged_sources_never_crash(sources: Path, tmp_path_factory: pytest.TempPathFactory, plan: list) -> None:
    root = tmp_path_factory.mktemp("damaged")
    touched = _damage(sources, root / "src", plan)
    build = _run(["db", "build", str(root / "src"), "--out", str(root / "out.sqlite")])
    _no_traceback(build)
    assert build.exit_code in (0, 1, 2, 3), build.output
    if build.exit_code != 0:
        assert any(name in build.output for name in touched), build.output
    check = _run(["db", "validate", str(root / "src"), "--format", "json"])
    _no_traceback(check)
    assert check.exit_code in (0, 1, 2, 3), check.output
    if check.exit_code == 2:  # unreadable for both, with the same one-line message
        assert build.exit_code == 2 and any(name in check.stderr for name in touched), check.stderr
    elif check.exit_code == 1:
        files = {Path(f.get("file") or "").name for f in _json(check)["findings"]}
        assert files & touched, check.stdout
