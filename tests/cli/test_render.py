"""Terminal tables never split a number across lines (issue 15), at 80 columns and piped."""

from __future__ import annotations

import io
import re

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rich.console import Console

from cli.render import frame_table, print_findings
from schemas.enums import Severity
from schemas.findings import Finding


def _render(table: object, width: int) -> str:
    buf = io.StringIO()
    Console(file=buf, width=width, color_system=None).print(table)
    return buf.getvalue()


numbers = st.one_of(
    st.integers(-(10**9), 10**9),
    st.floats(-1e9, 1e9, allow_nan=False, allow_infinity=False),
)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.tuples(numbers, numbers, st.integers(2, 999_999)), min_size=1, max_size=8),
    st.sampled_from([60, 80, 100]),
)
def test_findings_numbers_stay_whole(rows: list[tuple[float, float, int]], width: int) -> None:
    findings = [
        Finding(
            "log.gap",
            Severity.WARNING,
            "tacho",
            f"gap of {v} s from t = {lim} to {row} s (more than 3 cycles of 0.1 s)",
            file="/data/runs/2026-12-01/vehicle-0042/tacho.parquet",
            row=row,
            column="t",
            value=v,
            limit=lim,
        )
        for v, lim, row in rows
    ]
    buf = io.StringIO()
    print_findings(findings, Console(file=buf, width=width, color_system=None))
    text = buf.getvalue()
    table_lines = [line for line in text.splitlines() if line.startswith(("┃", "│", "┏", "└"))]
    assert all(len(line) <= width for line in table_lines)
    for f in findings:
        for cell in (_fmt(f.value), _fmt(f.limit), f"{f.file}:{f.row}"):
            assert cell in text, (cell, text)


def _fmt(v: object) -> str:
    from cli.render import _cell

    return _cell(v)


@pytest.mark.parametrize("width", [80, 100])
def test_frame_number_columns_never_wrap(width: int) -> None:
    frame = pd.DataFrame(
        {
            "line_code": ["0420", "0420"],
            "track": ["D", "U"],
            "direction": ["down", "up"],
            "n_corrections": [123456, 7],
            "mean_correction_pct": [0.123456, 12.5],
            "max_correction_pct": [1.98765, 0.5],
            "distance_m": [1234567.25, 98765.5],
            "refusal_reasons": ["entry_straight 2, min_speed 2, no_slip 2, upper_limit 1", ""],
        }
    )
    text = _render(frame_table(frame), width)
    for token in ("123456", "0.1235", "1.988", "1.235e+06", "9.877e+04"):
        assert re.search(rf"(?<![\d.]){re.escape(token)}(?![\d])", text), (token, text)


def test_a_frame_too_wide_for_80_columns_is_printed_as_records_with_every_column() -> None:
    """Eleven number columns and two text columns cannot share 80 columns: rather than the
    text columns shrinking out of sight, every row is printed as a record of label: value lines."""
    frame = pd.DataFrame(
        {
            "run_id": ["RUN-2026-12-01-vehicle-0042", "RUN-2026-12-01-vehicle-0043"],
            **{f"figure_{k}": [123456.25 + k, 7.5] for k in range(11)},
            "refusal_reasons": ["entry_straight 2, min_speed 2", "upper_limit 1"],
        }
    )
    wide = _render(frame_table(frame, title="Runs"), 400)
    assert "┃" in wide and "RUN-2026-12-01-vehicle-0042" in wide  # a table where it fits
    narrow = _render(frame_table(frame, title="Runs"), 80)
    assert "┃" not in narrow
    assert all(len(line) <= 80 for line in narrow.splitlines())
    lines = [" ".join(line.split()) for line in narrow.splitlines()]
    assert lines[:2] == ["Runs", "run: RUN-2026-12-01-vehicle-0042"]
    assert "figure 10: 1.235e+05" in lines and "failed diagnostics (count): upper_limit 1" in lines
    assert lines[lines.index("failed diagnostics (count): entry_straight 2, min_speed 2") + 1] == ""  # records apart
    assert narrow.splitlines()[1].index("RUN") == narrow.splitlines()[2].index("1.235e+05")  # values aligned


words = st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=30)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.lists(st.lists(words, min_size=1, max_size=6), min_size=4, max_size=4), min_size=1, max_size=5),
    st.integers(24, 160),
)
def test_any_table_keeps_its_borders_and_every_word_whole(rows: list[list[list[str]]], width: int) -> None:
    """Whatever the cells and the width: a table whose every line fits and ends in a border,
    or records; either way every word of every cell is printed whole (never split or cut)."""
    from cli.render import rows_table

    cells = [[" ".join(w) for w in r] for r in rows]
    text = _render(rows_table(["alpha", "beta gamma", "delta_m", "share [%]"], cells, title="T"), width)
    lines = text.splitlines()
    if "┃" in text:
        drawn = [line for line in lines if line[:1] in "┏┃┡│└"]
        assert all(len(line) <= width and line[-1] in "┓┃┩│┘" for line in drawn), text
    else:
        assert "alpha:" in text
    printed = [line.strip(" │┃") for line in lines]
    for word in {w for r in rows for c in r for w in c}:
        assert any(word in line for line in printed) or len(word) > width, (word, text)


def test_labels_and_shares_in_the_terminal() -> None:
    """The machine names read as words with their unit; a share (0–1) as a percentage."""
    frame = pd.DataFrame({"line_code": ["0420"], "mean_correction_pct": [1.25], "gps_trusted_share": [0.993]})
    text = _render(frame_table(frame), 120)
    assert "line" in text and "line_code" not in text and "mean correction [%]" in text
    assert "GPS trusted share" in text and "share [%]" not in text and "99.3 %" in text and "0.993" not in text


def test_frame_headers_and_cells_are_printed_as_written_not_as_markup() -> None:
    """ "[s]" is a unit (rich would read it as the strike-through tag and drop it)."""
    frame = pd.DataFrame({"stream": ["tacho [x]"], "t from [s]": [0.0], "declared [Hz]": [10]})
    text = _render(frame_table(frame), 80)
    assert "[s]" in text and "[Hz]" in text and "tacho [x]" in text


def test_long_columns_share_the_room_in_proportion_to_what_they_lack() -> None:
    # 80 columns: borders and padding take 7, so 73 for the text; column 1's longest word is 10
    # and its line 65 (lacks 55), column 2's 11 and 107 (lacks 96): the 52 spare characters go
    # 52·55/151 = 18.9 → 18 and 52·96/151 = 33.1 → 33, the one left over to the column that lacks
    # most — 28 and 45; the old rule (the nearly whole column first) gave 62 and 11
    from cli.render import fit_widths, rich_table

    table = rich_table()
    table.add_column("t")
    table.add_column("u")
    table.add_row(" ".join(["abcdefghij"] * 6), " ".join(["abcdefghijk"] * 9))
    assert fit_widths(table, 80) == [28, 45]
    # a short column lacking a few characters is still given them whole
    short = rich_table()
    short.add_column("key")
    short.add_column("text")
    short.add_row("ab cd", " ".join(["abcdefghijk"] * 9))
    assert fit_widths(short, 80)[0] == len("ab cd")
