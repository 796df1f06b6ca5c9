"""Workbooks that would build silently wrong DB content (issue 32 item 6): the sheet read is
the one named like the table, else the first visible one, never a hidden one silently; a
date in a text column is an error naming file, sheet, row and column."""

from __future__ import annotations

import datetime as dt
import shutil
from pathlib import Path

import openpyxl
import pandas as pd
import pytest

from dbtools.sample_network import sample_source_dir
from dbtools.sources import read_source_set
from dbtools.tabular import read_raw_table
from schemas.enums import Severity
from schemas.errors import InputError
from schemas.tables import BALISES


@pytest.fixture
def src(tmp_path: Path) -> Path:
    dst = tmp_path / "src"
    shutil.copytree(sample_source_dir(), dst)
    return dst


def _write(book: openpyxl.Workbook, ws: object, frame: pd.DataFrame) -> None:
    ws.append(list(frame.columns))  # type: ignore[attr-defined]
    for row in frame.itertuples(index=False):
        ws.append([v if v != "" else None for v in row])  # type: ignore[attr-defined]


def _balises_workbook(src: Path, sheets: list[tuple[str, str, pd.DataFrame]]) -> Path:
    """balises.csv replaced by a workbook of ``(title, state, frame)`` sheets, in order."""
    book = openpyxl.Workbook()
    book.remove(book.active)
    for title, state, frame in sheets:
        ws = book.create_sheet(title)
        _write(book, ws, frame)
        ws.sheet_state = state
    out = src / "balises.xlsx"
    book.save(out)
    (src / "balises.csv").unlink()
    return out


def _current_and_stale(src: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    current = pd.read_csv(src / "balises.csv", dtype=str, keep_default_na=False)
    stale = current.copy()
    stale["km_actual_m"] = "1.0"
    return current, stale


@pytest.mark.parametrize("state", ["hidden", "veryHidden"])
def test_a_hidden_first_sheet_is_not_read(src: Path, state: str) -> None:
    current, stale = _current_and_stale(src)
    path = _balises_workbook(src, [("old", state, stale), ("Sheet2", "visible", current)])
    net, findings = read_source_set(src)
    assert (net.balises["km_actual_m"] != 1.0).all()  # the visible sheet was read
    [note] = [f for f in findings if f.rule == "source.hidden_sheet"]
    assert note.severity == Severity.WARNING and note.file == str(path) and "'old'" in note.message
    assert "'Sheet2'" in note.message


def test_the_sheet_named_like_the_table_wins(src: Path) -> None:
    current, stale = _current_and_stale(src)
    _balises_workbook(src, [("notes", "visible", stale), ("balises", "visible", current)])
    net, findings = read_source_set(src)
    assert (net.balises["km_actual_m"] != 1.0).all()
    assert not [f for f in findings if f.rule.startswith("source.")]


def test_a_hidden_sheet_named_like_the_table_is_an_error(src: Path) -> None:
    current, _ = _current_and_stale(src)
    path = _balises_workbook(src, [("balises", "hidden", current), ("other", "visible", current)])
    _, findings = read_source_set(src)
    [err] = [f for f in findings if f.rule == "source.hidden_sheet"]
    assert err.severity == Severity.ERROR and err.file == str(path) and "'balises' is hidden" in err.message


def test_a_workbook_without_a_visible_sheet_is_refused(src: Path) -> None:
    current, _ = _current_and_stale(src)
    book = openpyxl.Workbook()
    ws = book.active
    ws.title = "x"
    _write(book, ws, current)
    book.create_sheet("y").sheet_state = "hidden"
    ws.sheet_state = "hidden"
    path = src / "lines.xlsx"
    # openpyxl refuses to save a workbook whose sheets are all hidden: make one visible, then hide it in the XML
    book.active = 1
    book["y"].sheet_state = "visible"
    book.save(path)
    _hide_all(path)
    with pytest.raises(InputError, match="no visible worksheet"):
        read_raw_table(path, sheet="lines", declared=BALISES)


def _hide_all(path: Path) -> None:
    import zipfile

    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    xml = members["xl/workbook.xml"].decode()
    xml = xml.replace('name="y" sheetId="2" state="visible"', 'name="y" sheetId="2" state="hidden"')
    assert 'state="visible"' not in xml
    members["xl/workbook.xml"] = xml.encode()
    with zipfile.ZipFile(path, "w") as z:
        for n, data in members.items():
            z.writestr(n, data)


def test_a_date_in_a_code_column_is_an_error_naming_sheet_cell_and_column(src: Path) -> None:
    current, _ = _current_and_stale(src)
    book = openpyxl.Workbook()
    ws = book.active
    ws.title = "balises"
    _write(book, ws, current)
    col = list(current.columns).index("station_code") + 1
    ws.cell(row=3, column=col).value = dt.datetime(2026, 1, 1)
    ws.cell(row=3, column=col).number_format = "yyyy-mm-dd"
    ws.cell(row=4, column=col + 2).value = dt.date(2026, 2, 1)  # signal_type: a text column, not a code
    ws.cell(row=4, column=col + 2).number_format = "yyyy-mm-dd"
    book.save(src / "balises.xlsx")
    (src / "balises.csv").unlink()
    _, findings = read_source_set(src)
    bad = [f for f in findings if f.rule == "source.date_in_text"]
    assert [(f.row, f.column) for f in bad] == [(3, "station_code"), (4, "signal_type")]
    first = bad[0]
    assert first.severity == Severity.ERROR and first.file == str(src / "balises.xlsx")
    assert "2026-01-01" in first.message and "sheet 'balises'" in first.message and "Text" in first.message
    with pytest.raises(InputError, match="date"):
        read_raw_table(src / "balises.xlsx", sheet="balises", declared=BALISES)
