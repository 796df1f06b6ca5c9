"""Spreadsheet locales of CSV inputs (dbtools/csv_locale.py): German, French and Finnish
source sets build the DB of their machine-format copy (same content hash) with one
``source.locale`` warning per file; declared conventions are obeyed and a file that
contradicts them refused; mixed, ambiguous and thousands-separated numbers refused naming
file, line and column; possession plans and mapped recorder CSV through the same mechanism."""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner, Result

from cli.main import app
from dbtools.build import build_db
from dbtools.csv_locale import CsvLocale, Dialect, consistent_delimiters, sniff_delimiter
from dbtools.sources import read_source_set
from dbtools.tabular import read_table_file
from dbtools.typed_csv import MACHINE, Notation, read_csv_typed
from fieldlogs.possession.plan import read_plan
from fieldlogs.recorders.importer import import_run
from schemas.enums import Severity
from schemas.errors import InputError, UsageError
from schemas.findings import Finding
from schemas.logs import LOG_STREAMS
from schemas.model import Table
from schemas.tables import GIS

DATA = Path(__file__).resolve().parents[1] / "data" / "european_csv"
RECORDERS = DATA.parent / "recorders"
LOCALES = ("de", "fr", "fi")
CSV_FILES = ("gis.csv", "balises.csv", "feature_points.csv", "lines.csv")


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "250"})


def locale_findings(findings: Sequence[Finding]) -> list[Finding]:
    return [f for f in findings if f.rule == "source.locale"]


@pytest.fixture
def de(tmp_path: Path) -> Path:
    dst = tmp_path / "de"
    shutil.copytree(DATA / "sources_de", dst)
    return dst


def edit_cell(path: Path, line: int, column: str, text: str, sep: str = ";") -> None:
    """Set one cell of a CSV (line 1 = header), keeping BOM and line ends."""
    raw = path.read_bytes()
    bom = raw.startswith(b"\xef\xbb\xbf")
    rows = raw.decode("utf-8-sig").split("\r\n")
    names = rows[0].split(sep)
    cells = rows[line - 1].split(sep)
    cells[names.index(column)] = text
    rows[line - 1] = sep.join(cells)
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + "\r\n".join(rows).encode("utf-8"))


# ------------------------------------------------------------------- source sets, end to end


def test_locale_source_sets_build_the_machine_db(tmp_path: Path) -> None:
    """The German (; , BOM CRLF), French (declared in network.toml) and Finnish (tabs)
    copies build the machine copy's DB: the same content hash."""
    ref = build_db(DATA / "sources_machine", tmp_path / "machine.sqlite", db_version="t1")
    assert not locale_findings(ref.warnings) and ref.rows["gis"] == 302
    for name in LOCALES:
        res = build_db(DATA / f"sources_{name}", tmp_path / f"{name}.sqlite", db_version="t1")
        assert res.content_hash == ref.content_hash, name
        assert res.rows == ref.rows


def test_one_finding_per_file_naming_it_and_the_convention() -> None:
    """302 GIS rows of decimal commas give one finding for gis.csv, not one per cell."""
    _, findings = read_source_set(DATA / "sources_de")
    found = locale_findings(findings)
    assert sorted(Path(str(f.file)).name for f in found) == sorted(CSV_FILES)
    assert all(f.severity == Severity.WARNING for f in found)
    gis = next(f for f in found if str(f.file).endswith("gis.csv"))
    assert gis.value == "`;`-separated with decimal commas (UTF-8 with a byte-order mark)"
    assert gis.message.startswith(gis.value) and str(DATA / "sources_de" / "gis.csv") == gis.file
    lines = next(f for f in found if str(f.file).endswith("lines.csv"))
    assert lines.value == "`;`-separated (UTF-8 with a byte-order mark)"  # no number column: no decimal claimed
    _, fi = read_source_set(DATA / "sources_fi")
    assert {f.value for f in locale_findings(fi) if str(f.file).endswith("gis.csv")} == {
        "tab-separated with decimal commas (UTF-8 with a byte-order mark)"
    }


def test_a_declared_convention_gives_no_finding(tmp_path: Path) -> None:
    _, fr = read_source_set(DATA / "sources_fr")  # network.toml [csv]
    assert not locale_findings(fr)
    _, de = read_source_set(DATA / "sources_de", CsvLocale(";", ","))
    assert not locale_findings(de)
    _, fi = read_source_set(DATA / "sources_fi", CsvLocale("tab", ","))
    assert not locale_findings(fi)


def test_options_come_before_network_toml(tmp_path: Path) -> None:
    src = tmp_path / "fr"
    shutil.copytree(DATA / "sources_fr", src)
    (src / "network.toml").write_text('[csv]\ndelimiter = ","\n', encoding="utf-8")
    with pytest.raises(InputError) as exc:
        read_source_set(src)
    assert "not comma-separated as network.toml [csv] says" in exc.value.message and exc.value.row == 1
    net, findings = read_source_set(src, CsvLocale(";"))
    found = sorted(Path(str(f.file)).name for f in locale_findings(findings))
    assert len(net.gis) == 302 and found == ["feature_points.csv", "gis.csv"]  # decimal commas detected


@pytest.mark.parametrize(
    ("toml", "words"),
    [
        ('[csv]\ndelimiter = "x"\n', "delimiter 'x'"),
        ('[csv]\ndecimal = ";"\n', "decimal separator ';'"),
        ('[csv]\ndelimiter = ","\ndecimal = ","\n', "needs another delimiter"),
        ('[csv]\nseparator = ";"\n', "unknown key(s) separator"),
        ("[csv]\ndecimal = 1\n", "are text"),
        ('csv = ";"\n', "unknown key(s) csv"),
    ],
)
def test_a_bad_csv_table_in_network_toml_is_refused(tmp_path: Path, toml: str, words: str) -> None:
    src = tmp_path / "fr"
    shutil.copytree(DATA / "sources_fr", src)
    (src / "network.toml").write_text(toml, encoding="utf-8")
    with pytest.raises(InputError) as exc:
        read_source_set(src)
    assert words in exc.value.message and exc.value.path == str(src / "network.toml")


# ------------------------------------------------------------------ refusals, naming the cell


def test_a_declared_delimiter_the_file_contradicts_is_refused(de: Path, tmp_path: Path) -> None:
    with pytest.raises(InputError) as exc:
        read_source_set(de, CsvLocale(","))
    assert exc.value.row == 1 and exc.value.path is not None and exc.value.path.endswith(".csv")
    assert "semicolon-separated" in exc.value.message and "not comma-separated as --delimiter says" in exc.value.message
    res = invoke("db", "build", de, "--out", tmp_path / "x.sqlite", "--delimiter", ",")
    assert res.exit_code == 2 and "Traceback" not in res.output and not (tmp_path / "x.sqlite").exists()


def test_a_declared_decimal_the_cells_contradict_is_refused(de: Path, tmp_path: Path) -> None:
    with pytest.raises(InputError) as exc:
        read_source_set(de, CsvLocale(decimal="."))
    assert (Path(exc.value.path or "").name, exc.value.row, exc.value.column) == ("gis.csv", 2, "lat")
    assert "'35,905939253' has a decimal comma, but --decimal says the decimal separator is '.'" in exc.value.message
    res = invoke("db", "validate", de, "--decimal", ".")
    assert res.exit_code == 2 and "gis.csv:2, column 'lat'" in " ".join(res.output.split())


def test_a_decimal_comma_cannot_go_with_a_comma_delimiter(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="needs another delimiter"):
        CsvLocale(",", ",")
    res = invoke(
        "db", "build", DATA / "sources_de", "--out", tmp_path / "x.sqlite", "--delimiter", ",", "--decimal", ","
    )
    assert res.exit_code == 2 and "needs another delimiter" in res.output
    with pytest.raises(InputError, match="comma-separated, so its decimal separator cannot be a comma"):
        read_source_set(DATA / "sources_machine", CsvLocale(decimal=","))  # detected ',' and declared ','


def test_an_unknown_option_value_is_refused(tmp_path: Path) -> None:
    res = invoke("db", "build", DATA / "sources_de", "--out", tmp_path / "x.sqlite", "--delimiter", ":")
    assert res.exit_code == 2 and "delimiter ':'" in res.output
    res = invoke("db", "validate", DATA / "sources_de", "--decimal", "dot")
    assert res.exit_code == 2 and "decimal separator 'dot'" in res.output


def test_mixed_decimal_separators_are_refused_naming_the_later_cell(de: Path) -> None:
    edit_cell(de / "gis.csv", 200, "lon", "139.47")
    with pytest.raises(InputError) as exc:
        read_source_set(de)
    assert (Path(exc.value.path or "").name, exc.value.row, exc.value.column) == ("gis.csv", 200, "lon")
    assert "'139.47' mixes decimal separators with '35,905939253' (line 2, column 'lat')" in exc.value.message
    with pytest.raises(InputError, match="has a decimal point, but --decimal says"):
        read_source_set(de, CsvLocale(decimal=","))  # declared: the same cell refused


THOUSANDS = ["16.350,5", "16,350.5", "1.016.350", "16 350,5", "16\u00a0350,5", "16'350.5", "16 350"]


@pytest.mark.parametrize("cell", THOUSANDS)
def test_a_thousands_separator_is_never_read_as_a_decimal(de: Path, cell: str) -> None:
    edit_cell(de / "balises.csv", 4, "km_actual_m", cell)
    for locale in (None, CsvLocale(";", ",")):
        with pytest.raises(InputError) as exc:
            read_source_set(de, locale)
        assert (Path(exc.value.path or "").name, exc.value.row, exc.value.column) == ("balises.csv", 4, "km_actual_m")
        assert "thousands separator" in exc.value.message


def test_three_digit_groups_alone_are_ambiguous_until_declared(tmp_path: Path) -> None:
    """``1,234`` in every number cell: a decimal comma or a thousands separator."""
    path = tmp_path / "plan.csv"
    machine = (DATA / "possessions_machine.csv").read_text(encoding="utf-8").splitlines()
    rows = [r.split(",") for r in machine]
    for r in rows[1:]:
        r[3], r[4] = "16,350", "16,750"
    path.write_text("\n".join(";".join(r) for r in rows) + "\n", encoding="utf-8")
    with pytest.raises(InputError) as exc:
        read_plan(path)
    assert (exc.value.row, exc.value.column) == (2, "km_from_m") and "ambiguous" in exc.value.message
    assert "--decimal" in exc.value.message
    plan = read_plan(path, locale=CsvLocale(decimal=","))
    assert [p.km_from_m for p in plan.possessions] == [16.35] * 3


def test_an_ambiguous_delimiter_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "gis.csv"
    path.write_text("line_code;track,km_m\n0420;D,16000\n0420;U,16020\n", encoding="utf-8")
    assert consistent_delimiters(path.read_bytes()) == {",": 2, ";": 2}
    with pytest.raises(InputError) as exc:
        sniff_delimiter(path, CsvLocale())
    assert exc.value.row == 1 and "ambiguous delimiter" in exc.value.message
    assert sniff_delimiter(path, CsvLocale(";")) == (";", False, False)  # declared: obeyed


def test_a_short_row_early_on_falls_back_to_the_header_for_the_parser_to_name(de: Path) -> None:
    path = de / "gis.csv"
    rows = path.read_bytes().split(b"\r\n")
    rows[4] += b";extra"
    path.write_bytes(b"\r\n".join(rows))
    assert sniff_delimiter(path, CsvLocale()) == (";", True, True)
    with pytest.raises(InputError) as exc:
        read_source_set(de)
    assert exc.value.row == 5 and "7 fields where the header has 6" in exc.value.message


def test_a_utf16_tab_file_excel_unicode_text_is_read_with_both_findings(tmp_path: Path) -> None:
    path = tmp_path / "gis.csv"
    text = (DATA / "sources_fi" / "gis.csv").read_text(encoding="utf-8-sig")
    path.write_bytes(text.encode("utf-16"))  # Excel "Unicode text": UTF-16 LE with BOM, tabs
    tf = read_table_file(path, table="gis", locale=CsvLocale(), numeric_columns=["km_m", "lat", "lon", "height_m"])
    assert sorted(f.rule for f in tf.findings) == ["source.encoding", "source.locale"]
    assert tf.frame["lat"].iat[0] == "35.905939253" and len(tf.frame) == 302


# --------------------------------------------------------------------------------- machine format


def test_the_typed_reader_reads_what_the_head_settles(monkeypatch: pytest.MonkeyPatch) -> None:
    """Machine files are read typed as before, with no finding; a locale file whose head
    settles its notation (decimal commas in gis and feature_points) is read typed in it;
    one whose head does not (balises: whole numbers only; lines: no number) as text."""
    seen: dict[str, Notation] = {}

    def spy(table: Table, path: Path, notation: Notation = MACHINE) -> pd.DataFrame | None:
        seen[path.name] = notation
        return read_csv_typed(table, path, notation)

    monkeypatch.setattr("dbtools.sources.read_csv_typed", spy)
    _, findings = read_source_set(DATA / "sources_machine")
    assert not locale_findings(findings) and seen == dict.fromkeys(CSV_FILES, MACHINE)
    seen.clear()
    _, findings = read_source_set(DATA / "sources_de")
    assert seen == {"gis.csv": Notation(";", ","), "feature_points.csv": Notation(";", ",")}
    assert len(locale_findings(findings)) == 4  # the same findings by either path
    seen.clear()
    read_source_set(DATA / "sources_fi", CsvLocale("tab", ","))
    assert set(seen) == set(CSV_FILES) and set(seen.values()) == {Notation("\t", ",")}  # declared: all typed


def test_a_bad_cell_beyond_the_head_sends_the_file_to_the_text_path_which_names_it(de: Path) -> None:
    edit_cell(de / "gis.csv", 250, "height_m", "55.020,5")
    assert read_csv_typed(GIS, de / "gis.csv", Notation(";", ",")) is None
    with pytest.raises(InputError) as exc:
        read_source_set(de)
    assert (Path(str(exc.value.path)).name, exc.value.row, exc.value.column) == ("gis.csv", 250, "height_m")
    assert "thousands separator" in exc.value.message


def test_dialect_description() -> None:
    assert Dialect(";", ",", True, frozenset({"delimiter"})).describe() == (
        "`;`-separated with decimal commas (UTF-8 with a byte-order mark)"
    )
    assert (
        Dialect("\t", ".", False, frozenset({"delimiter", "decimal"})).describe() == "tab-separated with decimal points"
    )
    assert Dialect(",", ".", False, frozenset({"decimal"})).finding(Path("x.csv"), "gis") is None
    assert Dialect(";", ",", False, frozenset()).finding(Path("x.csv"), "gis") is None  # all declared


# ----------------------------------------------------------------------------- possession plans


def test_a_german_plan_reads_as_its_machine_copy() -> None:
    de = read_plan(DATA / "possessions_de.csv")
    machine = read_plan(DATA / "possessions_machine.csv")
    assert not de.errors and de.possessions == machine.possessions
    assert [(p.km_from_m, p.km_to_m) for p in de.possessions] == [
        (16200.5, 17850.0),
        (16100.0, 18999.9),
        (17000.25, 17500.75),
    ]
    (f,) = de.findings
    assert (f.rule, f.file, f.value) == (
        "source.locale",
        str(DATA / "possessions_de.csv"),
        "`;`-separated with decimal commas (UTF-8 with a byte-order mark)",
    )
    assert not machine.findings
    declared = read_plan(DATA / "possessions_de.csv", locale=CsvLocale(";", ","))
    assert declared.possessions == machine.possessions and not declared.findings


def test_possession_check_refuses_a_plan_contradicting_decimal(tmp_path: Path) -> None:
    (tmp_path / "run").mkdir()
    db = tmp_path / "net.sqlite"
    build_db(DATA / "sources_machine", db, db_version="t1")
    res = invoke(
        "possession", "check", tmp_path / "run", "--db", db, "--plan", DATA / "possessions_de.csv", "--decimal", "."
    )
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert "possessions_de.csv:2, column 'km_from_m'" in " ".join(res.output.split())


# -------------------------------------------------------------------------- mapped recorder CSV


def test_a_german_mapped_csv_imports_as_its_machine_copy(tmp_path: Path) -> None:
    mapping, vehicle = RECORDERS / "imu_mapping.toml", RECORDERS / "vehicle.toml"
    ref = import_run([RECORDERS / "imu.csv"], tmp_path / "m", mapping=[mapping], vehicle=vehicle, run_id="r")
    res = import_run([DATA / "imu_de.csv"], tmp_path / "de", mapping=[mapping], vehicle=vehicle, run_id="r")
    a, b = pd.read_parquet(tmp_path / "m" / "imu.parquet"), pd.read_parquet(tmp_path / "de" / "imu.parquet")
    pd.testing.assert_frame_equal(a, b)
    assert res.start_time == ref.start_time
    (f,) = locale_findings(res.warnings)
    assert f.file == str(DATA / "imu_de.csv") and "decimal commas" in f.value
    assert not locale_findings(ref.warnings)


def test_a_mapped_csv_convention_declared_in_the_mapping_or_by_options(tmp_path: Path) -> None:
    vehicle = RECORDERS / "vehicle.toml"
    mapping = tmp_path / "imu.toml"
    mapping.write_text(
        (RECORDERS / "imu_mapping.toml").read_text(encoding="utf-8") + '\n[csv]\ndelimiter = ";"\ndecimal = ","\n',
        encoding="utf-8",
    )
    res = import_run([DATA / "imu_de.csv"], tmp_path / "a", mapping=[mapping], vehicle=vehicle)
    assert not locale_findings(res.warnings)
    res = import_run(
        [DATA / "imu_de.csv"], tmp_path / "b", mapping=[RECORDERS / "imu_mapping.toml"], vehicle=vehicle,
        locale=CsvLocale(";", ","),
    )  # fmt: skip
    assert not locale_findings(res.warnings)
    with pytest.raises(InputError) as exc:  # the options over the mapping
        import_run([DATA / "imu_de.csv"], tmp_path / "c", mapping=[mapping], vehicle=vehicle, locale=CsvLocale("tab"))
    assert exc.value.row == 1 and "semicolon-separated" in exc.value.message
    assert not (tmp_path / "c").exists()


def test_logs_import_options(tmp_path: Path) -> None:
    args = ["logs", "import", DATA / "imu_de.csv", "--mapping", RECORDERS / "imu_mapping.toml"]
    args += ["--vehicle", RECORDERS / "vehicle.toml"]
    res = invoke(*args, "--out", tmp_path / "x", "--decimal", ".")
    assert res.exit_code == 2 and "imu_de.csv:2, column 'acc_x'" in " ".join(res.output.split())
    res = invoke(*args, "--out", tmp_path / "y", "--delimiter", ";", "--decimal", ",")
    assert res.exit_code == 0, res.output
    assert "source.locale" not in res.output


# ------------------------------------------------------------------------------ property test

_VALUES = st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e12, max_value=1e12)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(_VALUES, _VALUES), min_size=1, max_size=30),
    st.sampled_from([";", "\t"]),
    st.booleans(),
)
def test_a_frame_round_trips_through_a_locale_csv(rows: list[tuple[float, float]], sep: str, bom: bool) -> None:
    """Written with decimal commas and ``sep`` (pandas's own writer, as a spreadsheet would),
    read back: the same floats, bit for bit; undeclared, the same or refused as ambiguous
    only when every decimal cell has three digits after its comma."""
    import tempfile

    frame = pd.DataFrame(rows, columns=["a", "b"])
    text = frame.to_csv(sep=sep, decimal=",", index=False)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.csv"
        path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8"))
        tf = read_table_file(path, locale=CsvLocale(sep, ","), numeric_columns=["a", "b"])
        for c in ("a", "b"):
            assert np.array_equal(pd.to_numeric(tf.frame[c]).to_numpy(dtype=float), frame[c].to_numpy())
        cells = [v for line in text.splitlines()[1:] for v in line.split(sep) if "," in v]
        try:
            detected = read_table_file(path, locale=CsvLocale(), numeric_columns=["a", "b"])
        except InputError as exc:
            assert "ambiguous" in exc.message
            assert cells and all(len(v.split(",")[1]) == 3 and len(v.lstrip("-").split(",")[0]) <= 3 for v in cells)
            return
        pd.testing.assert_frame_equal(detected.frame, tf.frame)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.tuples(_VALUES, _VALUES, _VALUES), min_size=1, max_size=30),
    st.sampled_from([";", "\t", "|"]),
    st.booleans(),
)
def test_the_typed_reader_in_a_locale_notation_reads_the_text_paths_numbers(
    rows: list[tuple[float, float, float]], sep: str, text_column: bool
) -> None:
    """Both typed parsers (pandas's C parser for a file of numbers, Arrow's with a text
    column) read decimal commas and another delimiter to the same floats as the text path,
    bit for bit."""
    import tempfile

    imu = LOG_STREAMS["imu"]
    table = GIS if text_column else Table("n", imu.kind, "numbers", tuple(imu.column(c) for c in ("t", "ax", "ay")))
    names = ["km_m", "lat", "lon"] if text_column else ["t", "ax", "ay"]
    frame = pd.DataFrame(rows, columns=names)
    if text_column:
        frame.insert(0, "line_code", "0420")
        frame.insert(1, "track", "D")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.csv"
        path.write_text(frame.to_csv(sep=sep, decimal=",", index=False), encoding="utf-8")
        typed = read_csv_typed(table, path, Notation(sep, ","))
        assert typed is not None
        text = read_table_file(path, locale=CsvLocale(sep, ","), numeric_columns=names).frame
        for c in names:
            want = frame[c].to_numpy()
            assert np.array_equal(typed[c].to_numpy(dtype=float), want)
            assert np.array_equal(pd.to_numeric(text[c]).to_numpy(dtype=float), want)


def test_a_mapped_csv_mixing_separators_past_the_head_is_refused_naming_the_cell(tmp_path: Path) -> None:
    """The head settles decimal commas (Arrow parses in them); a point on line 40 makes the
    parse fail, and the text path names the cell: nothing is written."""
    path = tmp_path / "imu_de.csv"
    shutil.copy(DATA / "imu_de.csv", path)
    edit_cell(path, 40, "acc_x", "0.010")
    with pytest.raises(InputError) as exc:
        import_run([path], tmp_path / "r", mapping=[RECORDERS / "imu_mapping.toml"], vehicle=RECORDERS / "vehicle.toml")
    assert (exc.value.row, exc.value.column) == (40, "acc_x") and "mixes decimal separators" in exc.value.message
    assert not (tmp_path / "r").exists()


def test_a_bad_csv_table_in_a_mapping_is_refused_naming_it(tmp_path: Path) -> None:
    mapping = tmp_path / "imu.toml"
    text = (RECORDERS / "imu_mapping.toml").read_text(encoding="utf-8")
    mapping.write_text(text + '\n[csv]\ndecimal = "·"\n', encoding="utf-8")
    with pytest.raises(InputError) as exc:
        import_run([DATA / "imu_de.csv"], tmp_path / "r", mapping=[mapping], vehicle=RECORDERS / "vehicle.toml")
    assert exc.value.path == str(mapping) and "imu.toml [csv]: decimal separator '·'" in exc.value.message


def test_excels_delimiter_hint_line_is_refused_naming_it(de: Path) -> None:
    path = de / "gis.csv"
    path.write_bytes(b"sep=;\r\n" + path.read_bytes().removeprefix(b"\xef\xbb\xbf"))
    with pytest.raises(InputError) as exc:
        read_source_set(de)
    assert (exc.value.path, exc.value.row) == (str(path), 1) and "Excel's delimiter hint" in exc.value.message
