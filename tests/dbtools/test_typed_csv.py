"""The typed CSV reader gives the text path's frame and findings, or declines (dbtools/typed_csv.py)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pyarrow as pa
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools import typed_csv
from dbtools.tabular import read_raw_table
from dbtools.typed_csv import TextPathNeeded, iter_csv_typed, read_csv_typed
from fieldlogs.runs.csv_reader import CsvStream
from fieldlogs.runs.typed import coerce_stream
from schemas.errors import InputError
from schemas.logs import LOG_STREAMS

NUMBER_CELLS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(repr),
    st.integers(-(10**6), 10**6).map(str),
    st.sampled_from(["", "nan", "NaN", "NA", "null", "NULL", "nAn", "inf", "-inf", "1e999", "x", "1,5", " 2", "3 "]),
    st.sampled_from(["1.50", "2.0", "-0", "+4", "1e3", "0x10", "-nan", " nan", "1_000"]),
    # whitespace the C parser skips around a number (C's isspace) and Arrow does not
    st.sampled_from(["\x0b1", "2\x0c", "\t", " ", "\x0b", "1e5\t", "\xa03"]),
    # NaN spellings: only the blank ones are nulls (pandas's own NA list is not used)
    st.sampled_from(["+nan", "nan ", "-NaN", "+NaN", "NULL ", "N/A", "#N/A", "None", "<NA>", "nan(1)", "1.#QNAN"]),
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
    frame, findings = CsvStream(LOG_STREAMS[name], path).read()
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


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.sampled_from(["gps", "balise", "cab"]),
    st.data(),
    st.lists(st.tuples(NUMBER_CELLS, NUMBER_CELLS, TEXT_CELLS, TEXT_CELLS), min_size=1, max_size=8),
)
def test_columns_in_any_order_absent_optional_ones_and_text_read_as_the_text_path(  # type: ignore[no-untyped-def]
    tmp_path: Path, name: str, data, rows
) -> None:
    """A stream with its columns shuffled, optional ones left out (or a required one), and
    text columns (padding, blanks, NA spellings, full-width letters): the typed path's
    frame, column order and findings are the text path's."""
    table = LOG_STREAMS[name]
    kinds = {c.name: c.dtype for c in table.columns}
    optional = [c.name for c in table.columns if not c.required]
    cols = [c.name for c in table.columns if c.required]
    cols += data.draw(st.lists(st.sampled_from(optional), unique=True)) if optional else []
    if data.draw(st.booleans()) and len(cols) > 1:  # a required column missing: the text path's finding
        cols.remove(data.draw(st.sampled_from([c for c in cols if c != "t"])))
    cols = data.draw(st.permutations(cols))
    lines = [",".join(cols)]
    for a, b, text, text2 in rows:
        cells = [
            (whole_cell(a if i % 2 else b) if kinds[c] == "int" else (a if i % 2 else b))
            if kinds[c] in ("float", "int")
            else (text if i % 2 else text2)
            for i, c in enumerate(cols)
        ]
        lines.append(",".join(csv_cell(cell) for cell in cells))
    path = tmp_path / f"{name}.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    same_as_text_path(name, path)


def test_a_stream_with_absent_optional_columns_and_text_is_read_typed(tmp_path: Path) -> None:
    """The shortcut is taken (no general coercion) and gives the text path's frame."""
    from schemas import frames

    path = tmp_path / "gps.csv"
    path.write_text("lon,t,lat,fix,nsat,hdop\n139.4,0,35.9,1,9,0.9\n139.5,1,,2,NA,1\n", encoding="utf-8")
    typed = read_csv_typed(LOG_STREAMS["gps"], path)
    assert typed is not None and frames._already_typed(LOG_STREAMS["gps"], typed) is not None
    same_as_text_path("gps", path)
    path = tmp_path / "balise.csv"
    path.write_text(
        "t,kind,line_code,station_code,track,signal_type\n1,I1,0420,,,\n1.5,I2 ,NULL,01,D,nAn\n", encoding="utf-8"
    )
    typed = read_csv_typed(LOG_STREAMS["balise"], path)
    assert typed is not None and frames._already_typed(LOG_STREAMS["balise"], typed) is not None
    frame, _ = CsvStream(LOG_STREAMS["balise"], path).read()
    assert frame["kind"].tolist() == ["I1", "I2"] and frame["line_code"].isna().tolist() == [False, True]
    assert frame["signal_type"].isna().all() and frame["line_code"].iloc[0] == "0420"
    same_as_text_path("balise", path)


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


FLAG_CELLS = st.sampled_from(
    ["", "1", "0", "true", "False", " YES", "n ", "y", "T", "f", "NA", "nan", "null", "2", "x", "yes.", "Ｙ", "\tno"]
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(FLAG_CELLS, FLAG_CELLS, TEXT_CELLS), min_size=1, max_size=8))
def test_flag_columns_read_and_check_as_text(tmp_path: Path, rows) -> None:  # type: ignore[no-untyped-def]
    """The tracks' buffer-stop flags: the typed shortcut (``frames._flags``) gives the text
    path's frame and findings, and is taken when every flag cell is a 0/1 word or blank."""
    from schemas import frames
    from schemas.tables import SOURCE_TABLES

    tracks = SOURCE_TABLES["tracks"]
    lines = ["track_id,line_code,kind,length_m,name,begin_buffer_stop,end_buffer_stop"]
    lines += [f"T{i},0001,station,10.5,{csv_cell(text)},{a},{b}" for i, (a, b, text) in enumerate(rows)]
    path = tmp_path / "tracks.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    typed = read_csv_typed(tracks, path)
    ours = frames.read_and_check(tracks, typed if typed is not None else read_raw_table(path), file=str(path))
    ref = frames.read_and_check(tracks, read_raw_table(path), file=str(path))
    pd.testing.assert_frame_equal(ours.frame, ref.frame, check_exact=True)
    assert [repr(f.__dict__) for f in ours.findings] == [repr(f.__dict__) for f in ref.findings]  # NaN-safe
    words = {"", "1", "0", "true", "false", "yes", "n", "y", "t", "f", "na", "nan", "null", "no"}
    if typed is not None and all(c.strip().lower() in words for a, b, _ in rows for c in (a, b)):
        assert frames._already_typed(tracks, typed) is not None


def test_flag_columns_by_hand() -> None:
    from schemas.frames import _flags

    text = pa.chunked_array([pa.array(["1", "no", None, "TRUE", "f"])])
    flags = _flags(text)
    assert flags is not None and flags.tolist() == [True, False, pd.NA, True, False]
    assert _flags(pa.chunked_array([pa.array(["1", "2"])])) is None  # "2" is no flag: the general path names it


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


@pytest.mark.parametrize(
    ("name", "body"),
    [
        ("cab", 't,direction\n0,"F"\n1,R\n'),  # a quoted text cell: the text path drops the quotes
        ("cab", 't,direction\n0,""\n1,R\n'),  # a quoted empty cell
        ("cab", 't,direction\n0,"F,R"\n1,R\n'),  # a quoted delimiter
        ("cab", 't,direction\n0,F"x\n1,R\n'),  # a quote inside a cell
        ("cab", '"t","direction"\n0,F\n1,R\n'),  # a quoted header
        ("imu", 't,ax,ay,az,wx,wy,wz\n0,"1.5",2,3,4,5,6\n'),  # a quoted number
        ("balise", 't,kind,line_code,station_code,track,signal_type\n1,"I1",0420,,"D",\n'),
    ],
)
def test_a_quoted_cell_is_read_as_the_text_path(tmp_path: Path, name: str, body: str) -> None:
    """Arrow parses without quote handling here (faster): any quote makes the file decline,
    for the text path to read it (bench/NOTES.md)."""
    path = tmp_path / f"{name}.csv"
    path.write_text(body, encoding="utf-8")
    assert read_csv_typed(LOG_STREAMS[name], path) is None
    same_as_text_path(name, path)


DIGITS = st.text("0123456789", min_size=1, max_size=25)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(DIGITS, DIGITS, st.integers(-340, 320), st.booleans()), min_size=1, max_size=40))
def test_the_c_parser_rounds_every_number_correctly(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, cells) -> None:  # type: ignore[no-untyped-def]
    """A file of number columns only is parsed by pandas's C parser (Arrow's path is not
    taken), and every value is the correctly rounded one (Python's float): up to 25
    significant digits, exponents near both ends of float64 (subnormals, underflow to 0)."""
    if not typed_csv.C_PARSER_EXACT:
        pytest.skip("pandas < 3.1: Arrow's parser reads every file")
    texts = [f"{'-' if neg else ''}{a}.{b}e{e}" for a, b, e, neg in cells]
    texts = [x for x in texts if abs(float(x)) < 1.7e308]
    if not texts:
        return
    path = tmp_path / "imu.csv"
    path.write_text("t,ax,ay,az,wx,wy,wz\n" + "".join(f"0,{x},1,2,3,4,5\n" for x in texts), encoding="utf-8")

    def no_arrow(*args: object) -> None:
        raise AssertionError("Arrow's path taken")

    monkeypatch.setattr(typed_csv, "_arrow_blocks", no_arrow)
    frame = read_csv_typed(LOG_STREAMS["imu"], path)
    assert frame is not None
    assert [v.hex() for v in frame["ax"].tolist()] == [float(x).hex() for x in texts]


@pytest.mark.parametrize(
    ("name", "body"),
    [
        ("tacho", "t,pulses\n0,1\n\n1,2\n"),  # an empty line (Arrow skips it)
        ("tacho", "t,pulses\n0,1\n1,2\n\n\n"),
        ("tacho", "t,pulses\n0,1\n  \n1,2\n"),  # a line of spaces (pandas would skip it)
        ("tacho", "t,pulses\n0,1\n\t\n1,2\n"),
        ("tacho", "t,pulses\r\n0,1\r\n1,2\r\n"),
        ("tacho", "\ufefft,pulses\n0,1\n1,2\n"),
        ("tacho", "t,pulses\n0,1\n1\n"),  # a short row
        ("tacho", "t,pulses\n0,1\n1,2,3\n"),  # a long row
        ("tacho", "t,pulses\n0,1,5\n1,2,6\n"),  # every row long (pandas: an index column)
        ("tacho", "t,pulses\n0,1,\n1,2,\n"),
        ("tacho", "t,pulses,\n0,1,\n1,2,\n"),
        ("tacho", "t,pulses\n0,1\n1,2"),  # no final line end
        ("tacho", "t,pulses\r0,1\r1,2\r"),  # carriage returns only
        ("tacho", "t,pulses\n0,1\n1,\x0b2\n"),  # a vertical tab: C's whitespace
        ("tacho", "t,pulses\n0,1\n#1,2\n"),
        ("tacho", "t,pulses\n0,1\n1,2\x00\n"),
        ("tacho", "t,pulses\n1e999,1\n"),
        ("tacho", "t,pulses\n0,2.5\n"),
        ("imu", "t,ax,ay,az,wx,wy,wz\n0,1,2,3,4,5,6\n,,,,,,\n"),
        ("imu", "t,ax,ay,az,wx,wy,wz\n0,1,2,3,4,5,inf\n"),
        ("imu", "t,ax,ay,az,wx,wy,wz\n0,1,2,3,4,5,1e308\n0,1,2,3,4,5,1e308\n"),  # a sum beyond float64
    ],
)
def test_line_shapes_of_a_number_file_read_as_the_text_path(tmp_path: Path, name: str, body: str) -> None:
    """Where pandas's C parser and Arrow's differ on a file's lines (pandas skips lines of
    spaces, fills short rows, takes a long first column for an index, skips C's whitespace
    around a number), the typed frame is still the text path's."""
    path = tmp_path / f"{name}.csv"
    path.write_bytes(body.encode("utf-8"))
    try:
        text_path(name, path)
    except InputError as exc:  # the text path refuses the file: so does the CSV reader, the same way
        with pytest.raises(InputError) as got:
            CsvStream(LOG_STREAMS[name], path).read()
        assert str(got.value) == str(exc)
        return
    same_as_text_path(name, path)


def _spread_file(tmp_path: Path, name: str, rows: int, blanks: list[int], bad: int | None, column: int = -1) -> Path:
    cols = LOG_STREAMS[name].column_names
    kinds = {c.name: c.dtype for c in LOG_STREAMS[name].columns}
    lines = [",".join(cols)]
    for k in range(rows):
        cells = [
            ("F" if k % 3 else "R") if kinds[c] == "str" else str(k if kinds[c] == "int" else k * 0.01 + i / 7)
            for i, c in enumerate(cols)
        ]
        if k in blanks:
            cells[column] = ""
        if k == bad:
            cells[0] = "x"
        lines.append(",".join(cells))
    path = tmp_path / f"{name}.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.sampled_from(["imu", "tacho", "gps", "cab"]),
    st.integers(0, 3000),
    st.integers(1, 1500),
    st.lists(st.integers(0, 2999), max_size=3),
    st.one_of(st.none(), st.integers(0, 2999)),
    st.integers(-1, 1),
)
def test_blocks_concatenate_to_the_whole_frame(  # type: ignore[no-untyped-def]
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, n: int, rows: int, blanks, bad, column: int
) -> None:
    """iter_csv_typed on files of many pieces and Arrow blocks (a piece with a blank read by
    Arrow, a bad cell deep in the file): frames of at most ``rows`` rows, parsed a piece
    of about ``rows`` rows at a time, whose concatenation is read_csv_typed's frame (index,
    dtypes, every value); None or TextPathNeeded exactly when read_csv_typed declines."""
    monkeypatch.setattr(typed_csv, "BLOCK_BYTES", 2048)
    monkeypatch.setattr(typed_csv, "PIECE_BYTES", 8192)
    path = _spread_file(tmp_path, name, n, blanks, bad, column)
    whole = read_csv_typed(LOG_STREAMS[name], path)
    pieces: list[int] = []
    c_numbers = typed_csv._c_numbers

    def counted(source, names, *notation):  # type: ignore[no-untyped-def]
        # the whole file (a path) or a piece of it (bytes _pos:_end, before it is read)
        size = (
            source.stat().st_size - len(path.read_bytes().split(b"\n", 1)[0]) - 1
            if isinstance(source, Path)
            else source._end - source._pos
        )
        pieces.append(size)
        return c_numbers(source, names, *notation)

    monkeypatch.setattr(typed_csv, "_c_numbers", counted)
    frames = iter_csv_typed(LOG_STREAMS[name], path, rows)
    if frames is None:
        assert whole is None
        return
    try:
        got = list(frames)
    except TextPathNeeded:
        assert whole is None
        return
    assert whole is not None
    assert all(0 < len(f) <= rows for f in got)
    line = max(len(x) for x in path.read_bytes().splitlines()) + 1
    assert all(p <= max(1 << 16, rows * line) + line for p in pieces)  # a piece of about ``rows`` rows
    pd.testing.assert_frame_equal(pd.concat(got), whole, check_exact=True)


def test_a_number_file_of_many_pieces_reads_as_the_text_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Pieces of a number file: the C parser's where it accepts them, Arrow's for the one
    with a blank (a null), the frame the text path's; a bad cell in the last piece declines."""
    monkeypatch.setattr(typed_csv, "PIECE_BYTES", 4096)
    path = _spread_file(tmp_path, "imu", 2000, [1500], None)
    arrow = typed_csv._arrow_blocks
    calls: list[object] = []

    def counted(*args):  # type: ignore[no-untyped-def]
        calls.append(args[0])
        return arrow(*args)

    monkeypatch.setattr(typed_csv, "_arrow_blocks", counted)
    frame = read_csv_typed(LOG_STREAMS["imu"], path)
    assert frame is not None and frame["wz"].isna().sum() == 1 and len(frame) == 2000
    # Arrow reads the one piece with the blank (C parser), or the whole file (pandas < 3.1)
    assert len(calls) == 1 and isinstance(calls[0], pa.NativeFile) == typed_csv.C_PARSER_EXACT
    same_as_text_path("imu", path)
    path = _spread_file(tmp_path, "imu", 2000, [1500], 1999)
    assert read_csv_typed(LOG_STREAMS["imu"], path) is None
    same_as_text_path("imu", path)
    calls.clear()  # blanks in another column than the last: nulls of the C parser's pieces
    path = _spread_file(tmp_path, "imu", 2000, [3, 1500, 1501], None, column=2)
    frame = read_csv_typed(LOG_STREAMS["imu"], path)
    assert frame is not None and frame["ay"].isna().sum() == 3 and len(frame) == 2000
    assert calls == [] or not typed_csv.C_PARSER_EXACT
    same_as_text_path("imu", path)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.text(alphabet=st.sampled_from(["a", "é", "漢", " ", "\t", '"', "\r", "\n", ",", "x"]), max_size=4)),
    st.integers(0, 3),
    st.booleans(),
)
def test_the_byte_test_of_text_cells_is_the_regular_expression(cells: list[str], cut: int, large: bool) -> None:
    """``_text_declines`` (bytes of the column) answers as ``match_substring_regex`` of
    ``_TEXT_DECLINES`` on every column, sliced ones (an offset into shared buffers) included."""
    import pyarrow.compute as pc

    a = pa.array(cells, type=pa.large_string() if large else pa.string()).slice(min(cut, len(cells)))
    want = bool(pc.any(pc.match_substring_regex(a, typed_csv._TEXT_DECLINES)).as_py())
    assert typed_csv._text_declines(a) == want


def test_the_byte_test_by_hand() -> None:
    assert not typed_csv._text_declines(pa.array(["a b", "", "x\t"]))
    assert typed_csv._text_declines(pa.array(["ab", " b"]))  # a padded cell
    assert typed_csv._text_declines(pa.array(["ab", "\tb"]))
    assert typed_csv._text_declines(pa.array(['a"b']))
    assert typed_csv._text_declines(pa.array(["a\rb"]))
    assert not typed_csv._text_declines(pa.array([" b", "c"]).slice(1))  # the padded cell sliced off
