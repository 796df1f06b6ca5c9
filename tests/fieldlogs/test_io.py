"""Run reader / writer: typed streams from CSV and Parquet, lazy loading, findings not exceptions."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from fieldlogs.runs import parquet_reader, typed
from fieldlogs.runs.handle import Run, read_run
from fieldlogs.runs.parquet_reader import ParquetStream
from fieldlogs.runs.write import check_output_folder, convert_run, write_run
from schemas.errors import FindingsError, InputError, RefusedError
from schemas.logs import LOG_STREAMS
from tests.fieldlogs.make_runs import make_meta, make_run, synthetic_streams


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_streams_are_typed_and_equal_in_both_formats(tmp_path: Path, fmt: str) -> None:
    run = read_run(make_run(tmp_path / "r", 3, fmt=fmt))
    assert run.meta is not None and run.meta.teeth == 90
    assert run.streams_present() == ["tacho", "imu", "balise", "gps", "cab"]
    tacho, imu, bal, gps, cab = (run.stream(n) for n in run.streams_present())
    assert tacho is not None and str(tacho["pulses"].dtype) == "Int64" and tacho["t"].dtype == np.float64
    assert imu is not None and len(imu) == 300 and all(imu[c].dtype == np.float64 for c in imu.columns)
    assert bal is not None and str(bal["kind"].dtype) == "string" and bal["line_code"].iloc[0] == "0420"
    assert bal["line_code"].isna().iloc[1]
    assert gps is not None and str(gps["fix"].dtype) == "Int64"
    assert cab is not None and cab["pto"].isna().all()
    assert run.findings == []
    expected = synthetic_streams(3)
    np.testing.assert_allclose(imu.to_numpy(dtype=float), expected["imu"].to_numpy(dtype=float), rtol=1e-9)
    assert tacho["pulses"].tolist() == expected["tacho"]["pulses"].tolist()


def test_csv_and_parquet_read_identically(tmp_path: Path) -> None:
    a = read_run(make_run(tmp_path / "csv", 2, fmt="csv"))
    b = read_run(make_run(tmp_path / "pq", 2, fmt="parquet"))
    for name in a.streams_present():
        fa, fb = a.stream(name), b.stream(name)
        assert fa is not None and fb is not None
        assert list(fa.dtypes.astype(str)) == list(fb.dtypes.astype(str)), name
        pd.testing.assert_frame_equal(fa, fb, check_exact=False, rtol=1e-9)


def test_streams_load_lazily(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "r", 2, fmt="parquet")
    (folder / "imu.parquet").write_bytes(b"not parquet")
    run = Run(folder)
    assert run.findings == []  # nothing read yet
    assert run.stream("tacho") is not None and run.findings == []
    assert run.stream("imu") is None
    (f,) = run.findings
    assert f.rule == "log.unreadable_stream" and f.file == str(folder / "imu.parquet")
    assert run.stream("radar") is None and not run.has("radar")


def test_parquet_text_in_numeric_column_names_row(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "r", 1, fmt="parquet")
    frame = synthetic_streams(1)["tacho"].astype({"pulses": str})
    frame.loc[4, "pulses"] = "abc"
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), folder / "tacho.parquet")
    run = Run(folder)
    tacho = run.stream("tacho")
    assert tacho is not None and str(tacho["pulses"].dtype) == "Int64" and tacho["pulses"].isna().sum() == 1
    (f,) = run.findings
    assert (f.rule, f.row, f.column, f.value) == ("schema.type", 4 + 2, "pulses", "abc")


def test_parquet_unit_metadata_is_checked(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "r", 1, fmt="parquet")
    table = pq.read_table(folder / "imu.parquet")
    assert table.schema.field("ax").metadata == {b"unit": "m/s²".encode()}
    i = table.schema.get_field_index("ax")
    table = table.set_column(i, table.schema.field("ax").with_metadata({"unit": "g"}), table.column("ax"))
    pq.write_table(table, folder / "imu.parquet")
    run = Run(folder)
    run.stream("imu")
    (f,) = run.findings
    assert (f.rule, f.column, f.value, f.limit) == ("log.unit", "ax", "g", "m/s²")


def test_parquet_int_time_and_float_pulses_are_accepted(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "r", 1, fmt="parquet")
    frame = pd.DataFrame({"t": np.arange(10), "pulses": np.arange(10, dtype=float)})
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), folder / "tacho.parquet")
    run = Run(folder)
    tacho = run.stream("tacho")
    assert tacho is not None and tacho["t"].dtype == np.float64 and str(tacho["pulses"].dtype) == "Int64"
    assert run.findings == []


def test_unreadable_run_folders_raise_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not a run folder"):
        Run(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"run\.json is missing"):
        Run(tmp_path / "empty")
    folder = make_run(tmp_path / "r", 1)
    (folder / "run.json").write_text("{not json", encoding="utf-8")
    with pytest.raises(InputError, match="not valid JSON") as exc:
        Run(folder)
    assert exc.value.path == str(folder / "run.json") and exc.value.row == 1
    (folder / "run.json").write_text("[1, 2]", encoding="utf-8")
    with pytest.raises(InputError, match="JSON object"):
        Run(folder)


def test_run_json_field_problems_are_findings(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "r", 1)
    data = json.loads((folder / "run.json").read_text(encoding="utf-8"))
    data.update(teeth="many", vehicle_kind="tram")
    del data["start_time"]
    (folder / "run.json").write_text(json.dumps(data), encoding="utf-8")
    run = Run(folder)
    assert run.meta is None
    assert {f.column for f in run.findings} == {"teeth", "vehicle_kind", "start_time"}
    assert all(f.file == str(folder / "run.json") for f in run.findings)
    assert run.field("wheel_diameter_m") == pytest.approx(0.86)  # still usable
    assert run.field("teeth") is None and run.vehicle_kind is None
    assert run.run_id == "R001"


def test_folder_contents_warnings(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "r", 1)
    (folder / "tacho.csv").rename(folder / "tach.csv")
    pq.write_table(pa.Table.from_pandas(synthetic_streams(1)["gps"]), folder / "gps.parquet")
    run = Run(folder)
    rules = {f.rule: f for f in run.findings}
    assert "misnamed 'tacho'" in rules["log.unknown_file"].message
    assert rules["log.duplicate_stream_file"].file == str(folder / "gps.csv")
    assert run.stream_format("gps") == "parquet" and not run.has("tacho")


def test_write_run_refuses_existing_and_replaces_with_force(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "r", 1)
    with pytest.raises(RefusedError):
        write_run(folder, make_meta(), synthetic_streams(1))
    write_run(folder, make_meta("R002"), synthetic_streams(1), fmt="parquet", force=True)
    assert Run(folder).run_id == "R002" and (folder / "tacho.parquet").exists()
    assert not list(tmp_path.glob(".*"))  # no temp folders left


def test_check_output_folder(tmp_path: Path) -> None:
    src = tmp_path / "run"
    for bad in (src, src / "inside", tmp_path):
        with pytest.raises(RefusedError):
            check_output_folder(src, bad)
    check_output_folder(src, tmp_path / "other")


def test_convert_round_trip(tmp_path: Path) -> None:
    src = make_run(tmp_path / "csv", 2)
    res = convert_run(src, tmp_path / "pq", "parquet")
    assert res.rows["imu"] == 200
    back = convert_run(tmp_path / "pq", tmp_path / "csv2", "csv")
    assert back.format == "csv"
    for name in ("tacho", "imu", "gps", "balise", "cab"):
        a, b = Run(src).stream(name), Run(tmp_path / "csv2").stream(name)
        pd.testing.assert_frame_equal(a, b)
    with pytest.raises(RefusedError):
        convert_run(src, tmp_path / "pq", "parquet")
    with pytest.raises(RefusedError):
        convert_run(src, src, "parquet", force=True)


def test_convert_refuses_cells_it_would_lose(tmp_path: Path) -> None:
    src = make_run(tmp_path / "r", 1)
    text = (src / "imu.csv").read_text(encoding="utf-8").splitlines()
    text[3] = text[3].replace(text[3].split(",")[1], "oops", 1)
    (src / "imu.csv").write_text("\n".join(text) + "\n", encoding="utf-8")
    with pytest.raises(FindingsError) as exc:
        convert_run(src, tmp_path / "out", "parquet")
    assert exc.value.findings[0].row == 4 and exc.value.findings[0].column == "ax"
    assert not (tmp_path / "out").exists()


def test_parquet_fast_path_has_no_per_cell_python(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Written-by-us Parquet never goes through the text coercion."""
    folder = make_run(tmp_path / "r", 2, fmt="parquet")

    def boom(*a: object, **k: object) -> None:
        raise AssertionError("coerce_frame called on typed Parquet")

    monkeypatch.setattr(typed, "coerce_frame", boom)
    monkeypatch.setattr(parquet_reader, "coerce_frame", boom)
    assert len(Run(folder).load_all()) == 5


def test_parquet_read_a_column_at_a_time_equals_the_whole_table(tmp_path: Path) -> None:
    """Many row groups, nulls in an int column, an optional column absent, an unknown
    column: the same frame and findings as one row group read whole."""
    gps = synthetic_streams(60)["gps"].drop(columns=["speed_mps"], errors="ignore")
    gps["nsat"] = gps["nsat"].astype("Int64")
    gps.loc[3, "nsat"] = None
    gps["extra"] = 1.0
    table = pa.Table.from_pandas(gps, preserve_index=False)
    pq.write_table(table, tmp_path / "one.parquet")
    pq.write_table(table, tmp_path / "many.parquet", row_group_size=7)
    assert pq.ParquetFile(tmp_path / "many.parquet").metadata.num_row_groups > 3
    whole, f_whole = ParquetStream(LOG_STREAMS["gps"], tmp_path / "one.parquet").read()
    parts, f_parts = ParquetStream(LOG_STREAMS["gps"], tmp_path / "many.parquet").read()
    pd.testing.assert_frame_equal(whole, parts, check_exact=True)
    assert list(whole.columns) == LOG_STREAMS["gps"].column_names and whole["nsat"].isna().sum() == 1
    assert (
        [(f.rule, f.column) for f in f_parts]
        == [(f.rule, f.column) for f in f_whole]
        == [("schema.unknown_column", "extra")]
    )


def test_released_stream_is_read_again_and_its_findings_are_kept_once(tmp_path: Path) -> None:
    folder = make_run(tmp_path / "r", 1, fmt="parquet")
    table = pq.read_table(folder / "imu.parquet")
    i = table.schema.get_field_index("ax")
    table = table.set_column(i, table.schema.field("ax").with_metadata({"unit": "g"}), table.column("ax"))
    pq.write_table(table, folder / "imu.parquet")
    run = Run(folder)
    first = run.stream("imu")
    assert first is not None and run.loaded("imu") and len(run.findings) == 1
    run.release("imu")
    assert not run.loaded("imu") and len(run.findings) == 1 and len(run.stream_findings("imu")) == 1
    again = run.stream("imu")
    assert again is not None and again is not first
    pd.testing.assert_frame_equal(first, again, check_exact=True)
    assert len(run.findings) == 1  # not reported twice
    run.release("radar")  # not loaded, not present: nothing to do
    assert not run.loaded("radar")
