"""Kilometrages are plausible (issue 32 item 6): every km column within the range declared
once in schemas (``KM_PLAUSIBLE_M``), and a balise's equipment km within the validation
config's tolerance of its actual km — in source sets and DBs, so that ``validate --strict``
(and so ``db release``) refuses 23469.0 → 234690.0 and 1e308."""

from __future__ import annotations

import shutil
import sqlite3
from contextlib import closing
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.rules.config import ValidationConfig
from dbtools.sample_network import sample_source_dir
from dbtools.validate import validate_path
from schemas.catalog import ALL_SCHEMAS
from schemas.model import KM_PLAUSIBLE_M
from schemas.tables import BALISES


def test_every_km_column_declares_the_plausible_range() -> None:
    km = [(t.name, c) for t in ALL_SCHEMAS.values() for c in t.columns if c.km_notation]
    assert len(km) >= 10
    for name, c in km:
        assert c.min is not None and c.max is not None, (name, c.name)
        assert -KM_PLAUSIBLE_M <= c.min < c.max <= KM_PLAUSIBLE_M, (name, c.name)


@pytest.fixture
def src(tmp_path: Path) -> Path:
    dst = tmp_path / "src"
    shutil.copytree(sample_source_dir(), dst)
    return dst


def _set(src: Path, column: str, value: str, row: int = 0) -> None:
    path = src / "balises.csv"
    frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    frame.loc[row, column] = value
    frame.to_csv(path, index=False)


@pytest.mark.parametrize("column", ["km_actual_m", "km_equipment_m"])
@pytest.mark.parametrize("value", ["1e308", "-2000001", "2500000"])
def test_implausible_km_in_a_source_is_a_range_error(src: Path, column: str, value: str) -> None:
    _set(src, column, value)
    findings = validate_path(src)
    hits = [f for f in findings if f.rule == "schema.range" and f.column == column]
    assert hits and hits[0].row == 2 and hits[0].file == str(src / "balises.csv")


def test_km_equipment_off_by_a_digit_is_an_error_with_both_values(src: Path) -> None:
    frame = pd.read_csv(src / "balises.csv", dtype=str, keep_default_na=False)
    actual = float(frame.loc[0, "km_actual_m"])
    _set(src, "km_equipment_m", repr(actual * 10))
    [f] = [f for f in validate_path(src) if f.rule == "balise.km_equipment"]
    assert f.value == {"km_equipment_m": actual * 10, "km_actual_m": actual}
    assert f.limit == ValidationConfig().km_equipment_tolerance_m == 1000.0
    assert f.row == 2 and f.column == "km_equipment_m"


def test_a_small_equipment_offset_is_fine(src: Path) -> None:
    frame = pd.read_csv(src / "balises.csv", dtype=str, keep_default_na=False)
    _set(src, "km_equipment_m", repr(float(frame.loc[0, "km_actual_m"]) + 999.0))
    assert not [f for f in validate_path(src) if f.rule == "balise.km_equipment"]


@pytest.mark.parametrize(
    ("sql", "rule"),
    [
        ("km_equipment_m = km_actual_m * 10", "balise.km_equipment"),
        ("km_equipment_m = 1e308", "schema.range"),
        ("km_actual_m = 9e15", "schema.range"),
        ("link_distance_m = 1e308", "schema.range"),
    ],
)
def test_a_db_with_an_implausible_km_fails_strict_validation(
    tmp_path: Path, sample_db: Path, sql: str, rule: str
) -> None:
    db = tmp_path / "db.sqlite"
    shutil.copyfile(sample_db, db)
    with closing(sqlite3.connect(db)) as conn, conn:
        conn.execute(f"UPDATE {BALISES.name} SET {sql} WHERE rowid = 1")
    assert rule in {f.rule for f in validate_path(db)}
    res = CliRunner().invoke(app, ["db", "validate", str(db), "--strict"])
    assert res.exit_code == 1, res.output


@pytest.mark.parametrize("column", ["nid_c", "nid_bg", "n_pig", "n_total"])
@pytest.mark.parametrize("value", ["1e308", "inf", "99999"])
def test_balise_group_integers_are_checked(src: Path, column: str, value: str) -> None:
    _set(src, column, value)
    hits = [f for f in validate_path(src) if f.column == column]
    assert hits and hits[0].rule in ("schema.type", "schema.range") and hits[0].row == 2
