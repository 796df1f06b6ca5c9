"""What people's spreadsheet tools write, read by db build / db validate (dbtools/tabular.py):
wrong delimiter, unclosed quotes, duplicated headers, numeric codes in .xlsx, Shift-JIS,
header-only tables, BOM — each a clear finding or message naming file, line and column,
the same through the typed fast path (dbtools/typed_csv.py) as through the text path."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import openpyxl
import pandas as pd
import pytest
from typer.testing import CliRunner, Result

import dbtools.sources as sources
from cli.main import app
from dbtools.build import build_db
from dbtools.database import write_db
from dbtools.network import content_hash
from dbtools.sample_network import sample_source_dir
from dbtools.sources import read_source_set
from dbtools.tabular import read_raw_table, read_table_file
from dbtools.typed_csv import read_csv_typed
from dbtools.validate import validate_path
from schemas.enums import Severity
from schemas.errors import FindingsError, InputError
from schemas.tables import BALISES, FEATURE_POINTS


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "250"})


@pytest.fixture
def src(tmp_path: Path) -> Path:
    dst = tmp_path / "src"
    shutil.copytree(sample_source_dir(), dst)
    return dst


def lines(path: Path) -> list[str]:
    return path.read_text(encoding="utf-8").split("\n")


def write_lines(path: Path, rows: list[str]) -> None:
    path.write_text("\n".join(rows), encoding="utf-8")


def errors(findings: list[object]) -> list[object]:
    return [f for f in findings if getattr(f, "severity", None) == Severity.ERROR]


def assert_build_refused(folder: Path, out: Path, code: int) -> Result:
    res = invoke("db", "build", folder, "--out", out, "--version", "t1")
    assert res.exit_code == code, res.output
    assert "Traceback" not in res.output and not out.exists()
    return res


# ------------------------------------------------------------------------------ delimiter


@pytest.mark.parametrize(("sep", "word"), [(";", "semicolons"), ("\t", "tabs"), ("|", "vertical bars")])
def test_another_delimiter_is_read_in_a_source_set_and_refused_in_machine_files(
    src: Path, tmp_path: Path, sep: str, word: str
) -> None:
    """A source set saved with another delimiter is read in it, with one source.locale
    warning (dbtools.csv_locale); a file that must be in the machine format (a run folder's
    stream) is refused naming the delimiter."""
    path = src / "balises.csv"
    write_lines(path, [r.replace(",", sep) for r in lines(path)])
    net, findings = read_source_set(src)
    assert not errors(findings)
    (f,) = [f for f in findings if f.file == str(path)]  # one finding, not one per cell
    assert (f.rule, f.severity) == ("source.locale", Severity.WARNING)
    assert len(net.balises) == len(lines(sample_source_dir() / "balises.csv")) - 2
    with pytest.raises(InputError, match=word):  # log streams: refused outright
        read_raw_table(path)
    tf = read_table_file(path, table="balises")
    ((f,),) = [errors(tf.findings)]
    assert (f.rule, f.file, f.row, f.value) == ("source.delimiter", str(path), 1, sep)
    assert word in f.message and "not commas" in f.message


# ---------------------------------------------------------------------------------- quotes


def test_a_quote_never_closed_is_refused_naming_line_and_column(src: Path, tmp_path: Path) -> None:
    path = src / "feature_points.csv"
    rows = lines(path)
    rows[5] = rows[5].replace(",", ',"', 1)  # line 6: 0420,"D,F001,…
    write_lines(path, rows)
    assert read_csv_typed(FEATURE_POINTS, path) is None  # Arrow would read the rest as one cell
    with pytest.raises(InputError) as exc:
        read_source_set(src)
    assert (exc.value.path, exc.value.row, exc.value.column) == (str(path), 6, "track")
    assert "never closed" in exc.value.message
    res = assert_build_refused(src, tmp_path / "x.sqlite", 2)
    assert f"{path}:6, column 'track'" in " ".join(res.stderr.split())
    assert invoke("db", "validate", src).exit_code == 2


def test_a_stray_quote_swallowing_rows_is_refused(src: Path, tmp_path: Path) -> None:
    """One quote opened on line 6 and another at the end of line 41: 35 lines read as one
    cell, which a parser accepts silently (db build once kept 18 of 108 rows)."""
    path = src / "feature_points.csv"
    rows = lines(path)
    rows[5] = rows[5].replace(",", ',"', 1)
    rows[40] += '"'
    write_lines(path, rows)
    assert read_csv_typed(FEATURE_POINTS, path) is None
    with pytest.raises(InputError) as exc:
        read_table_file(path)
    assert (exc.value.row, exc.value.column) == (6, "track") and "spans lines 6–41" in exc.value.message
    assert_build_refused(src, tmp_path / "x.sqlite", 2)


def test_too_many_fields_names_the_line(src: Path) -> None:
    path = src / "balises.csv"
    rows = lines(path)
    rows[3] += ",extra"
    write_lines(path, rows)
    with pytest.raises(InputError) as exc:
        read_source_set(src)
    assert exc.value.row == 4 and "needs quotes" in exc.value.message


# ------------------------------------------------------------------------------- headers


def test_a_duplicated_header_names_the_real_column(src: Path, tmp_path: Path) -> None:
    path = src / "balises.csv"
    rows = lines(path)
    rows[0] = rows[0].replace("km_equipment_m", "km_actual_m")
    write_lines(path, rows)
    _, findings = read_source_set(src)
    rules = {(f.rule, f.column) for f in findings}
    assert ("source.duplicate_column", "km_actual_m") in rules
    assert ("schema.missing_column", "km_equipment_m") in rules
    assert not any("km_actual_m.1" in f.message for f in findings)  # pandas' mangled name never shows
    dup = next(f for f in findings if f.rule == "source.duplicate_column")
    assert dup.row == 1 and "columns 7, 8" in dup.message
    assert_build_refused(src, tmp_path / "x.sqlite", 1)


# ---------------------------------------------------------------------------------- codes


def workbook(csv_path: Path, out: Path, numeric: Callable[[str, str], tuple[object, str] | None]) -> Path:
    """``csv_path`` as a one-sheet workbook; ``numeric(column, text)`` gives (value, number
    format) for cells to store as numbers, None to keep text."""
    frame = pd.read_csv(csv_path, dtype=str, keep_default_na=False)
    book = openpyxl.Workbook()
    ws = book.active
    ws.title = csv_path.stem
    ws.append(list(frame.columns))
    for r, row in enumerate(frame.itertuples(index=False), start=2):
        for c, (name, text) in enumerate(zip(frame.columns, row, strict=True), start=1):
            cell = ws.cell(row=r, column=c)
            got = numeric(name, text)
            if got is None:
                cell.value = text if text != "" else None
            else:
                cell.value, cell.number_format = got
    book.save(out)
    return out


def test_numeric_station_codes_in_xlsx_are_errors_naming_the_cell(src: Path, tmp_path: Path) -> None:
    csv_path = src / "balises.csv"
    workbook(csv_path, src / "balises.xlsx", lambda c, t: (int(t), "General") if c == "station_code" else None)
    csv_path.unlink()
    _, findings = read_source_set(src)
    bad = [f for f in findings if f.rule == "source.numeric_code"]
    assert bad and all(f.column == "station_code" and f.severity == Severity.ERROR for f in bad)
    first = bad[0]
    assert (first.row, first.file) == (2, str(src / "balises.xlsx"))
    assert first.message.startswith("cell D2 holds the number 1, not text") and "leading zeros" in first.message
    assert_build_refused(src, tmp_path / "x.sqlite", 1)
    assert invoke("db", "validate", src).exit_code == 1


def test_numeric_codes_formatted_with_zeros_are_read_as_displayed(src: Path, tmp_path: Path) -> None:
    csv_path = src / "balises.csv"
    expected = pd.read_csv(csv_path, dtype=str, keep_default_na=False)
    workbook(
        csv_path,
        src / "balises.xlsx",
        lambda c, t: (int(t), "0" * len(t)) if c in ("station_code", "line_code") else None,
    )
    csv_path.unlink()
    net, findings = read_source_set(src)
    assert not errors(findings)
    got = net.balises.set_index("balise_id")
    for row in expected.itertuples(index=False):
        assert (got.at[row.balise_id, "station_code"], got.at[row.balise_id, "line_code"]) == (
            row.station_code,
            row.line_code,
        )
    with_csv, _ = read_source_set(sample_source_dir())
    assert content_hash(net.tables) == content_hash(with_csv.tables)  # the same DB as from the CSV


def test_numbers_in_free_text_and_number_columns_of_xlsx_are_fine(src: Path) -> None:
    csv_path = src / "feature_points.csv"
    workbook(csv_path, src / "feature_points.xlsx", lambda c, t: (float(t), "General") if c.endswith("_m") else None)
    csv_path.unlink()
    net, findings = read_source_set(src)
    assert not errors(findings)
    with_csv, _ = read_source_set(sample_source_dir())
    pd.testing.assert_frame_equal(net.feature_points, with_csv.feature_points)


# ------------------------------------------------------------------------------- encoding


def test_shift_jis_is_read_with_a_warning_naming_the_encoding(src: Path, tmp_path: Path) -> None:
    path = src / "lines.csv"
    path.write_bytes("line_code,name,operator\n0420,川越線,ＪＲ東日本\n".encode("cp932"))
    net, findings = read_source_set(src)
    (note,) = [f for f in findings if f.rule == "source.encoding"]
    assert note.severity == Severity.WARNING and note.value == "Shift-JIS (CP932)" and note.row == 2
    assert "read as Shift-JIS (CP932)" in note.message
    assert net.lines["name"].tolist() == ["川越線"]
    assert "ＪＲ東日本" in net.lines["attributes_json"].iat[0]
    out = tmp_path / "net.sqlite"
    res = invoke("db", "build", src, "--out", out, "--version", "t1")
    assert res.exit_code == 0 and out.exists() and "Shift-JIS" in res.output
    assert invoke("db", "validate", src, "--strict").exit_code == 1  # a warning: CI may ask for UTF-8


def test_utf16_with_bom_is_read_with_a_warning(src: Path) -> None:
    path = src / "lines.csv"
    path.write_bytes("line_code,name\n0420,川越線\n".encode("utf-16"))
    net, findings = read_source_set(src)
    assert [f.value for f in findings if f.rule == "source.encoding"] == ["UTF-16"]
    assert net.lines["name"].tolist() == ["川越線"]


def test_an_encoding_that_is_neither_is_refused_naming_the_line(src: Path) -> None:
    path = src / "lines.csv"
    path.write_bytes(b"line_code,name\n0420,ok\n0421,\xff\xfe bad\n")
    with pytest.raises(InputError) as exc:
        read_source_set(src)
    assert exc.value.row == 3 and "nor Shift-JIS" in exc.value.message and exc.value.path == str(path)


def test_a_utf8_bom_changes_nothing(src: Path, tmp_path: Path) -> None:
    clean, clean_findings = read_source_set(src)
    for name in ("balises", "gis", "feature_points", "lines"):
        path = src / f"{name}.csv"
        path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    net, findings = read_source_set(src)
    assert content_hash(net.tables) == content_hash(clean.tables)
    assert [f.rule for f in findings] == [f.rule for f in clean_findings]


# ---------------------------------------------------------------------------- empty tables


def test_header_only_balises_is_a_finding_not_a_crash(src: Path, tmp_path: Path) -> None:
    """A warning: trains cannot use such a DB, the GPS-based possession check can."""
    path = src / "balises.csv"
    write_lines(path, [lines(path)[0], ""])
    _, findings = read_source_set(src)
    (f,) = [f for f in findings if f.rule == "schema.empty_table"]
    assert (f.severity, f.file, f.table) == (Severity.WARNING, str(path), "balises")
    assert "header but no rows" in f.message and "initial position" in f.message
    res = invoke("db", "build", src, "--out", tmp_path / "x.sqlite", "--version", "t1")
    assert res.exit_code == 0 and "schema.empty_table" in res.output  # built, with the warning shown
    res = invoke("db", "validate", src, "--format", "json", "--strict")
    assert res.exit_code == 1 and '"schema.empty_table"' in res.stdout


def test_header_only_gis_is_an_error_and_feature_points_none(src: Path, tmp_path: Path) -> None:
    for name in ("gis", "feature_points"):
        write_lines(src / f"{name}.csv", [lines(src / f"{name}.csv")[0]])
    _, findings = read_source_set(src)
    (f,) = [f for f in findings if f.rule == "schema.empty_table"]  # a network without curves is possible
    assert (f.table, f.severity, f.row) == ("gis", Severity.ERROR, 2) and "no GIS grid" in f.message
    assert_build_refused(src, tmp_path / "x.sqlite", 1)


def test_an_empty_table_in_a_db_file_is_a_finding(tmp_path: Path) -> None:
    net, _ = read_source_set(sample_source_dir())
    net.tables[BALISES.name] = net.balises.iloc[0:0]
    db = tmp_path / "empty.sqlite"
    write_db(db, net, {"db_version": "t", "content_hash": content_hash(net.tables), "created_at": "x",
                       "tool_version": "x", "schema_version": "1"})  # fmt: skip
    found = [f for f in validate_path(db) if f.rule == "schema.empty_table"]
    assert [(f.table, f.severity) for f in found] == [("balises", Severity.WARNING)]
    assert found[0].message.startswith("table 'balises' has no rows")


# --------------------------------------------------------------- the typed path agrees


def _cases(root: Path) -> dict[str, Path]:
    """One damaged copy of the sample source set per case above (CSV only)."""
    out: dict[str, Path] = {}

    def case(name: str, edit: Callable[[Path], None]) -> None:
        folder = root / name
        shutil.copytree(sample_source_dir(), folder)
        edit(folder)
        out[name] = folder

    def rewrite(file: str, fn: Callable[[list[str]], list[str]]) -> Callable[[Path], None]:
        return lambda f: write_lines(f / file, fn(lines(f / file)))

    case("clean", lambda f: None)
    case("semicolon", rewrite("balises.csv", lambda r: [x.replace(",", ";") for x in r]))
    case("duplicate", rewrite("balises.csv", lambda r: [r[0].replace("km_equipment_m", "km_actual_m"), *r[1:]]))
    case("header_only", rewrite("balises.csv", lambda r: [r[0]]))
    case("bom", lambda f: (f / "gis.csv").write_bytes(b"\xef\xbb\xbf" + (f / "gis.csv").read_bytes()))
    case("sjis", lambda f: (f / "lines.csv").write_bytes("line_code,name\n0420,川越線\n".encode("cp932")))
    case("padded", rewrite("gis.csv", lambda r: [r[0], *(" " + x if x else x for x in r[1:])]))
    return out


def test_typed_and_text_paths_give_the_same_networks_and_findings(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cases = _cases(tmp_path)
    typed = {name: read_source_set(folder) for name, folder in cases.items()}
    monkeypatch.setattr(sources, "read_csv_typed", lambda *args: None)  # every file as text
    for name, folder in cases.items():
        net, findings = read_source_set(folder)
        t_net, t_findings = typed[name]
        assert content_hash(net.tables) == content_hash(t_net.tables), name
        assert [f.to_dict() for f in findings] == [f.to_dict() for f in t_findings], name


def test_build_refuses_every_error_case(tmp_path: Path) -> None:
    for name, folder in _cases(tmp_path / "cases").items():
        _, findings = read_source_set(folder)
        out = tmp_path / f"{name}.sqlite"
        if errors(findings):
            with pytest.raises(FindingsError):
                build_db(folder, out, db_version="t1")
            assert not out.exists(), name
        else:
            build_db(folder, out, db_version="t1")
