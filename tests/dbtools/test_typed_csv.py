"""The typed CSV reader gives the text path's frame and findings, or declines (dbtools/typed_csv.py)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools import typed_csv
from dbtools.tabular import read_raw_table
from dbtools.typed_csv import read_csv_typed
from fieldlogs.io import coerce_stream, read_stream
from schemas.logs import LOG_STREAMS

NUMBER_CELLS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(repr),
    st.integers(-(10**6), 10**6).map(str),
    st.sampled_from(["", "nan", "NaN", "NA", "null", "NULL", "nAn", "inf", "-inf", "1e999", "x", "1,5", " 2", "3 "]),
    st.sampled_from(["1.50", "2.0", "-0", "+4", "1e3", "0x10", "-nan", " nan", "1_000"]),
)


def whole_cell(cell: str) -> str:
    """The cell, unless the text path itself fails on it in a whole-number column (infinite
    or beyond int64: pandas raises while casting)."""
    try:
        return "x" if abs(float(cell)) >= 1e15 else cell
    except ValueError:
        return cell


TEXT_CELLS = st.one_of(
    st.sampled_from(["F", "R", "", "NA", "nan", " F", "F ", "x,y", "I1", "Ｆ"]), st.text("abcRF ", max_size=3)
)


def text_path(name: str, path: Path) -> tuple[pd.DataFrame, list]:  # type: ignore[type-arg]
    return coerce_stream(LOG_STREAMS[name], read_raw_table(path), str(path))


def csv_cell(cell: str) -> str:
    return f'"{cell}"' if "," in cell else cell


def same_as_text_path(name: str, path: Path) -> None:
    ref_frame, ref_findings = text_path(name, path)
    frame, findings = read_stream(LOG_STREAMS[name], path)
    pd.testing.assert_frame_equal(frame, ref_frame, check_exact=True)
    assert [repr(f.__dict__) for f in findings] == [repr(f.__dict__) for f in ref_findings]  # NaN-safe


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.sampled_from(["imu", "tacho", "cab"]),
    st.lists(st.tuples(NUMBER_CELLS, NUMBER_CELLS, TEXT_CELLS), min_size=1, max_size=8),
    st.booleans(),
)
def test_typed_reading_is_the_text_path(tmp_path: Path, name: str, rows, extra_column: bool) -> None:  # type: ignore[no-untyped-def]
    cols = LOG_STREAMS[name].column_names
    header = cols + (["spare"] if extra_column else [])
    lines = [",".join(header)]
    for a, b, text in rows:
        whole = whole_cell(b)
        cells = {"t": a, "pulses": whole, "direction": text, "pto": whole}
        cells.update({c: (a if i % 2 else b) for i, c in enumerate(cols) if c not in cells})
        lines.append(",".join([csv_cell(cells[c]) for c in cols] + (["1"] if extra_column else [])))
    path = tmp_path / f"{name}.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    same_as_text_path(name, path)


def test_a_clean_file_is_read_typed(tmp_path: Path) -> None:
    path = tmp_path / "imu.csv"
    path.write_text("t,ax,ay,az,wx,wy,wz\n0.0,1,2,3,4,5,6\n0.01,,NA,nan,0.5,-1e-3,7\n", encoding="utf-8")
    typed = read_csv_typed(LOG_STREAMS["imu"], path)
    assert typed is not None and typed["ax"].dtype == "float64"
    same_as_text_path("imu", path)


@pytest.mark.parametrize(
    "body",
    [
        "t,pulses\n0.0,1.5\n",  # fractional whole number: the text path names '1.5'
        "t,pulses\n0.0,1e999\n",  # infinite
        "t,pulses\n0.0,x\n",  # not a number
        "t,pulses,pulses\n0.0,1,2\n",  # repeated column
        "t,pulses\n",  # header only
    ],
)
def test_what_the_text_path_must_judge_declines(tmp_path: Path, body: str) -> None:
    path = tmp_path / "tacho.csv"
    path.write_text(body, encoding="utf-8")
    assert read_csv_typed(LOG_STREAMS["tacho"], path) is None


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(NUMBER_CELLS, NUMBER_CELLS, TEXT_CELLS), min_size=1, max_size=8))
def test_a_source_file_reads_and_checks_as_text(tmp_path: Path, rows) -> None:  # type: ignore[no-untyped-def]
    from schemas.frames import read_and_check
    from schemas.tables import GIS

    lines = [",".join(GIS.column_names)]
    for a, b, text in rows:
        cells = {"line_code": text, "track": text, "km_m": a, "lat": b, "lon": a, "height_m": b}
        lines.append(",".join(csv_cell(cells[c]) for c in GIS.column_names))
    path = tmp_path / "gis.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    typed = read_csv_typed(GIS, path)
    ours = read_and_check(GIS, typed if typed is not None else read_raw_table(path), file=str(path))
    ref = read_and_check(GIS, read_raw_table(path), file=str(path))
    pd.testing.assert_frame_equal(ours.frame, ref.frame, check_exact=True)
    assert [repr(f.__dict__) for f in ours.findings] == [repr(f.__dict__) for f in ref.findings]  # NaN-safe


@pytest.mark.parametrize("name", ["imu", "cab"])
def test_many_blocks_and_rows_shorter_than_the_first_block_read_as_the_text_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str
) -> None:
    """A file of many parse blocks whose later rows are much shorter than the first ones
    (the arrays are sized from the first block, then grown): the text path's frame, every
    value in place; a bad cell deep in the file still declines."""
    monkeypatch.setattr(typed_csv, "BLOCK_BYTES", 4096)
    cols = LOG_STREAMS[name].column_names
    kinds = {c.name: c.dtype for c in LOG_STREAMS[name].columns}
    wide = {"float": "{k}.11111111111111", "int": "{k:014d}", "str": "F"}
    long = [",".join(wide[kinds[c]].format(k=k) for c in cols) for k in range(100)]
    short = [",".join(str(k % 7) if c != "direction" else ("R" if k % 3 else "") for c in cols) for k in range(6000)]
    path = tmp_path / f"{name}.csv"
    path.write_text("\n".join([",".join(cols), *long, *short]) + "\n", encoding="utf-8")
    typed = read_csv_typed(LOG_STREAMS[name], path)
    assert typed is not None and len(typed) == 6100
    assert typed["t"].iloc[99] == float(f"99.{'1' * 14}") and typed["t"].iloc[-1] == 5999 % 7
    same_as_text_path(name, path)
    path.write_text(path.read_text(encoding="utf-8").replace("\n3,", "\n3x,", 1), encoding="utf-8")
    assert read_csv_typed(LOG_STREAMS[name], path) is None
    same_as_text_path(name, path)
