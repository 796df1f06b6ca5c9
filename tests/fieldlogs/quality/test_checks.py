"""``logs check`` rules: each damage gives its finding with file, row (file line) and column."""

from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools.build import build_db
from fieldlogs.quality.checks import CheckLimits, DbRefs, check_run, load_db_refs
from fieldlogs.runs.write import write_run
from schemas.errors import InputError, TrainposError
from schemas.findings import Finding
from tests.conftest import DATA
from tests.fieldlogs.make_runs import make_meta, make_run, synthetic_streams


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> DbRefs:
    out = tmp_path_factory.mktemp("db") / "tiny.sqlite"
    build_db(DATA / "tiny_sources", out, db_version="t1")
    return load_db_refs(out)


def edit_csv(folder: Path, name: str, fn: Callable[[pd.DataFrame], pd.DataFrame]) -> Path:
    """Rewrite one CSV stream through ``fn`` (cells as text)."""
    path = folder / f"{name}.csv"
    frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    fn(frame).to_csv(path, index=False, lineterminator="\n")
    return path


def line(path: Path, row: int) -> str:
    return path.read_text(encoding="utf-8").splitlines()[row - 1]


def by_rule(findings: list[Finding], rule: str) -> list[Finding]:
    return [f for f in findings if f.rule == rule]


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
@pytest.mark.parametrize("kind", ["train", "road_rail"])
def test_clean_runs_have_no_findings(tmp_path: Path, db: DbRefs, fmt: str, kind: str) -> None:
    assert check_run(make_run(tmp_path / "r", 10, fmt=fmt, vehicle_kind=kind), db) == []


def test_unsorted_rows(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 3)
    path = edit_csv(run, "tacho", lambda f: f.iloc[[0, 1, 2, 4, 3, *range(5, len(f))]])
    (f,) = check_run(run)
    assert (f.rule, f.file, f.row, f.column) == ("log.unsorted", str(path), 6, "t")
    assert line(path, 6).startswith("0.3,")


def test_duplicate_rows_and_times(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 3)

    def damage(f: pd.DataFrame) -> pd.DataFrame:
        other = f.iloc[[10]].copy()
        other["ax"] = "0.5"
        return pd.concat([f.iloc[:11], f.iloc[[5]], other, f.iloc[11:]])

    path = edit_csv(run, "imu", damage)
    findings = check_run(run)
    unsorted = by_rule(findings, "log.unsorted")
    assert [x.row for x in unsorted] == [13]  # line 13 holds t of row 5 after t of row 10
    (dup_row,) = by_rule(findings, "log.duplicate_row")
    (dup_t,) = by_rule(findings, "log.duplicate_t")
    assert (dup_row.row, dup_row.file) == (13, str(path))
    assert dup_t.row == 14 and line(path, 14).startswith("0.1,0.5,")


def test_gap(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 3)
    path = edit_csv(run, "tacho", lambda f: f.drop(index=[10, 11, 12]))
    (f,) = check_run(run)
    assert (f.rule, f.severity, f.row, f.file) == ("log.gap", "warning", 12, str(path))
    assert f.value == pytest.approx(0.4) and f.limit == pytest.approx(0.3)
    edit_csv(run, "tacho", lambda f: f.drop(index=[20, 21]))  # 3 cycles (0.3 s): not a gap
    assert [f.row for f in check_run(run)] == [12]


def test_wrong_sampling_rate(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 3)
    path = edit_csv(run, "imu", lambda f: f.iloc[::2])  # 50 Hz
    (f,) = check_run(run)
    assert (f.rule, f.file, f.row) == ("log.rate", str(path), None)
    assert f.value == pytest.approx(50.0) and f.limit == 100.0


def test_pulse_reset_and_decrease(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 10)

    def damage(f: pd.DataFrame) -> pd.DataFrame:
        p = f["pulses"].astype(int).to_numpy().copy()
        p[60:] -= p[59]  # counter reset right after row 59
        p[80] -= 20  # a glitch
        f["pulses"] = p.astype(str)
        return f

    path = edit_csv(run, "tacho", damage)
    findings = check_run(run)
    (reset,) = by_rule(findings, "log.pulse_reset")
    assert (reset.row, reset.column, reset.file) == (62, "pulses", str(path))
    (dec,) = by_rule(findings, "log.pulse_decrease")
    assert dec.row == 82
    assert by_rule(findings, "log.speed_jump")  # the glitch is also a speed jump


def test_speed_jump(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 10)

    def damage(f: pd.DataFrame) -> pd.DataFrame:
        p = f["pulses"].astype(int).to_numpy().copy()
        p[50:] += 200  # 200 pulses (~6 m) in one cycle: slip
        f["pulses"] = p.astype(str)
        return f

    edit_csv(run, "tacho", damage)
    jumps = by_rule(check_run(run), "log.speed_jump")
    assert [j.row for j in jumps] == [52, 53]  # up, then back down
    assert jumps[0].value > 0 > jumps[1].value and jumps[0].severity == "warning"


def test_values_nan_and_out_of_range(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 2)

    def damage(f: pd.DataFrame) -> pd.DataFrame:
        f.loc[5, "ax"] = "45"
        f.loc[7, "wz"] = "-3.5"
        f.loc[9, "ay"] = "NaN"
        f.loc[11, "az"] = "abc"
        return f

    path = edit_csv(run, "imu", damage)
    found = {(f.rule, f.row, f.column) for f in check_run(run)}
    assert found == {
        ("schema.range", 7, "ax"),
        ("schema.range", 9, "wz"),
        ("schema.null", 11, "ay"),
        ("schema.type", 13, "az"),
    }
    assert all(f.file == str(path) for f in check_run(run))


def test_imu_logged_in_g(tmp_path: Path) -> None:
    streams = synthetic_streams(2)
    streams["imu"][["ax", "ay", "az"]] /= 9.80665
    run = write_run(tmp_path / "r", make_meta(), streams, fmt="csv")
    (f,) = check_run(run)
    assert f.rule == "log.unit_suspect" and "looks like g" in f.message


def test_gps_outside_db_area(tmp_path: Path, db: DbRefs) -> None:
    run = make_run(tmp_path / "r", 10)

    def damage(f: pd.DataFrame) -> pd.DataFrame:
        f.loc[[3, 4, 5], "lat"] = "35.0"
        f.loc[8, "fix"] = "0"
        f.loc[8, "lon"] = "140.5"  # no fix: not judged
        return f

    path = edit_csv(run, "gps", damage)
    assert check_run(run) == []  # without a DB nothing to compare with
    (f,) = check_run(run, db)
    assert (f.rule, f.row, f.column, f.file) == ("log.gps_outside_area", 5, "lat", str(path))
    assert "3 fix(es) (lines 5–7)" in f.message


def test_balise_codes_against_db(tmp_path: Path, db: DbRefs) -> None:
    streams = synthetic_streams(10)
    streams["balise"] = pd.DataFrame(
        {
            "t": [1.0, 1.5, 3.0, 3.5, 5.0, 6.0, 7.0, 8.0],
            "kind": ["I1", "I2", "I1", "I2", "C", "I2", "I1", "I2"],
            "line_code": ["0420", None, "9999", None, None, "0420", None, None],
            "station_code": [None, "01", None, "01", None, "02", None, None],
            "track": [None, "D", None, "D", None, "D", None, "U"],
            "signal_type": [None, None, None, None, "S1", None, None, None],
        }
    )
    run = write_run(tmp_path / "r", make_meta(), streams, fmt="csv")
    found = {(f.rule, f.row, f.column) for f in check_run(run, db)}
    assert found == {
        ("log.balise_unknown_line", 4, "line_code"),  # I1 9999
        ("log.balise_unknown_pair", 5, "station_code"),  # I2 01/D after I1 9999
        ("log.balise_unknown_signal", 6, "signal_type"),  # C S1: the DB has no C balise
        ("log.balise_unknown_pair", 7, "station_code"),  # own line 0420, station 02
        ("log.balise_field", 8, "line_code"),  # I1 without a line
        ("log.balise_field", 9, "station_code"),  # I2 without a station
    }
    without_db = {f.rule for f in check_run(run)}
    assert without_db == {"log.balise_field"}


def test_stream_from_another_run(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 5)
    other = make_run(tmp_path / "other", 5, t_offset=3600.0)
    (run / "imu.csv").write_bytes((other / "imu.csv").read_bytes())
    (f,) = check_run(run)
    assert (f.rule, f.file, f.column) == ("log.no_overlap", str(run / "imu.csv"), "t")
    assert "does not overlap tacho" in f.message


@pytest.mark.parametrize(("kind", "drop", "rule"), [("train", "imu", "log.missing_stream"), ("road_rail", "cab", None)])
def test_required_streams(tmp_path: Path, kind: str, drop: str, rule: str | None) -> None:
    run = make_run(tmp_path / "r", 2, vehicle_kind=kind)
    (run / f"{drop}.csv").unlink()
    (f,) = check_run(run)
    assert (f.rule, f.file, f.value) == ("log.missing_stream", str(run), drop)
    assert kind in f.message


def test_optional_stream_may_be_missing(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 2)
    (run / "gps.csv").unlink()
    (run / "balise.csv").unlink()
    assert check_run(run) == []


def test_empty_and_header_only_streams(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 2)
    (run / "tacho.csv").write_text("t,pulses\n", encoding="utf-8")
    (run / "gps.csv").write_text("", encoding="utf-8")
    found = {(f.rule, f.severity, f.file) for f in check_run(run)}
    assert found == {
        ("log.empty_stream", "error", str(run / "tacho.csv")),  # required for a train
        ("log.unreadable_stream", "error", str(run / "gps.csv")),
    }


def test_findings_are_capped_per_rule(tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 5)
    edit_csv(run, "imu", lambda f: f.assign(wz="9"))
    findings = check_run(run, limits=CheckLimits(max_per_rule=10))
    assert len(findings) == 11 and findings[-1].value == 500


def test_row_numbers_of_parquet_are_index_plus_two(tmp_path: Path) -> None:
    streams = synthetic_streams(3)
    streams["tacho"].loc[7, "pulses"] = -1
    run = write_run(tmp_path / "r", make_meta(), streams, fmt="parquet")
    ranges = [f for f in check_run(run) if f.rule == "schema.range"]
    assert [(f.row, f.file) for f in ranges] == [(9, str(run / "tacho.parquet"))]


def test_unreadable_run_raises_only_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError):
        check_run(tmp_path / "nope")


def test_db_refs_from_tiny_db(db: DbRefs) -> None:
    assert "0420" in db.line_codes and ("0420", "01", "D") in db.i2_keys and db.signal_types == frozenset()
    assert db.bbox is not None and db.bbox[0] == pytest.approx(35.9)


# --- damaged logs: properties --------------------------------------------------------------

DAMAGES = ("shuffle", "truncate", "text", "empty", "header_only", "foreign", "garbage", "drop_column")


_TEMPLATES: dict[tuple[str, float], Path] = {}


def clean_copy(dest: Path, fmt: str, t_offset: float = 0.0) -> Path:
    """A copy of a cached clean 2-second run (generating and compressing it once per format)."""
    key = (fmt, t_offset)
    if key not in _TEMPLATES or not _TEMPLATES[key].exists():
        base = Path(tempfile.mkdtemp(prefix="trainpos-runs-"))
        _TEMPLATES[key] = make_run(base / "run", 2, fmt=fmt, t_offset=t_offset)  # type: ignore[arg-type]
    return Path(shutil.copytree(_TEMPLATES[key], dest))


def damage_run(folder: Path, damage: str, stream: str, data: st.DataObject) -> Path:
    """Apply one damage to one stream file; return the damaged file."""
    files = {p.stem: p for p in folder.iterdir() if p.stem == stream}
    path = files[stream]
    raw = path.read_bytes()
    if damage == "shuffle":
        frame = pd.read_csv(path, dtype=str, keep_default_na=False) if path.suffix == ".csv" else None
        if frame is not None:
            seed = data.draw(st.integers(0, 2**16), label="seed")
            frame.sample(frac=1.0, random_state=seed).to_csv(path, index=False)
    elif damage == "truncate":
        path.write_bytes(raw[: data.draw(st.integers(0, len(raw)), label="cut")])
    elif damage == "text":
        if path.suffix == ".csv":
            lines = raw.decode().splitlines()
            i = data.draw(st.integers(1, max(len(lines) - 1, 1)), label="line")
            if i < len(lines):
                lines[i] = "x1," + lines[i].split(",", 1)[-1]
            path.write_text("\n".join(lines) + "\n")
        else:
            path.write_bytes(raw[:10] + b"text" + raw[14:])
    elif damage == "empty":
        path.write_bytes(b"")
    elif damage == "header_only":
        path.write_text(",".join(pd.read_csv(path, nrows=0).columns) + "\n" if path.suffix == ".csv" else "t\n")
    elif damage == "foreign":
        other = clean_copy(folder.parent / f"other-{folder.name}", path.suffix[1:], t_offset=500.0)
        path.write_bytes((other / path.name).read_bytes())
    elif damage == "garbage":
        path.write_bytes(data.draw(st.binary(min_size=1, max_size=64), label="bytes"))
    elif damage == "drop_column":
        if path.suffix == ".csv":
            frame = pd.read_csv(path, dtype=str, keep_default_na=False)
            frame.drop(columns=[frame.columns[-1]]).to_csv(path, index=False)
    return path


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    damage=st.sampled_from(DAMAGES),
    stream=st.sampled_from(["tacho", "imu", "gps", "balise", "cab"]),
    fmt=st.sampled_from(["csv", "parquet"]),
    data=st.data(),
)
def test_damaged_logs_give_findings_naming_files(
    tmp_path_factory: pytest.TempPathFactory, damage: str, stream: str, fmt: str, data: st.DataObject
) -> None:
    folder = clean_copy(tmp_path_factory.mktemp("prop") / "run", fmt)
    path = damage_run(folder, damage, stream, data)
    try:
        findings = check_run(folder)
    except TrainposError:
        return  # typed, reported as exit 2 by the CLI
    assert all(f.file for f in findings), [str(f) for f in findings if not f.file]
    json.dumps([f.to_dict() for f in findings])
    if damage in ("empty", "foreign", "garbage") or (damage == "header_only" and stream in ("tacho", "imu")):
        assert any(f.file == str(path) for f in findings), (damage, [str(f) for f in findings])
