"""The HTML page kit: escaping, tables from DataFrames, embedded figures, badges, legend, the
page skeleton, and matplotlib imported only when a figure is drawn."""

from __future__ import annotations

import base64
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from dbtools import pagekit as kit
from tests.fresh import fresh_python
from tests.pages import check_page


class Cells(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.cells: list[tuple[str | None, str]] = []
        self.tags: list[str] = []
        self._td: str | bool | None = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        if tag == "td":
            self._td = dict(attrs).get("class")
            self.cells.append((self._td, ""))
        else:
            self._td = False

    def handle_data(self, data: str) -> None:
        if self._td is not False and self.cells:
            cls, text = self.cells[-1]
            self.cells[-1] = (cls, text + data)


def parse(html: str) -> Cells:
    p = Cells()
    p.feed(html)
    return p


def test_frame_table_escapes_and_formats_numbers() -> None:
    frame = pd.DataFrame(
        {"name": ["<b>x</b>", None], "n": [1234567, 3], "x": [1234.5678, 0.12345], "flag": [True, False]}
    )
    frame["gap"] = [np.nan, 2.0]
    html = kit.frame_table(frame)
    assert "<b>x</b>" not in html and "&lt;b&gt;x&lt;/b&gt;" in html
    cells = parse(html).cells
    assert cells[:5] == [("l", "<b>x</b>"), (None, "1,234,567"), (None, "1,235"), ("l", "True"), (None, "")]
    assert cells[5:] == [(None, ""), (None, "3"), (None, "0.123"), ("l", "False"), (None, "2.000")]


def test_cell_function_refines_columns() -> None:
    def cell(column: str, v: object) -> kit.Cell:
        return kit.Cell(f"{float(v):.1f} %", "warn") if column == "share" else kit.default_cell(column, v)  # type: ignore[arg-type]

    cells = parse(kit.frame_table(pd.DataFrame({"share": [12.34], "k": [2]}), cell)).cells
    assert cells == [("warn", "12.3 %"), (None, "2")]


def test_page_skeleton_badge_legend_and_key_values() -> None:
    html = kit.page(
        "t <1>",
        kit.paragraph("a & b", kit.Status.NOTE),
        kit.badge("3 alarm(s)", kit.Status.ALARM),
        kit.legend({"overrun": "outside <the> section"}, "Alarms:"),
        kit.key_value_table([("run", "runs/a"), ("n", 3)], code=("run",)),
        kit.section("Part", "<p>x</p>", level=3),
        heading_text="Heading",
        verdict=kit.Verdict("Passed: 0 errors, 1 warning", kit.Status.OK),
    )
    assert "<h1>Heading</h1>\n<p id='verdict' class='verdict ok'>Passed: 0 errors, 1 warning</p>" in html
    assert html.startswith("<!doctype html><html lang='en'><head><meta charset='utf-8'>")
    assert "<title>t &lt;1&gt;</title>" in html and "<h1>Heading</h1>" in html and html.endswith("</body></html>")
    assert "<p class='note'>a &amp; b</p>" in html and "<span class='badge alarm'>3 alarm(s)</span>" in html
    assert "<dt>overrun</dt><dd>outside &lt;the&gt; section</dd>" in html
    assert "<tr><th>run</th><td><code>runs/a</code></td></tr><tr><th>n</th><td>3</td></tr>" in html
    assert "<h3>Part</h3>\n<p>x</p>" in html
    assert "<script" not in html and "http" not in html.split("<body>")[1]


def test_figure_is_an_embedded_png() -> None:
    plt = kit.pyplot()
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    ax.set(xlabel="t [s]", ylabel="km\n[m]")
    data = kit.png(fig)
    assert data.axes == "x: t [s]; y: km [m]"
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    html = kit.figure(data, 'a "quoted" alt', "caption")
    src = html.split('src="', 1)[1].split('"', 1)[0]
    head, b64 = src.split(",", 1)
    assert head == "data:image/png;base64" and base64.b64decode(b64) == data
    assert (
        'alt="a &quot;quoted&quot; alt (x: t [s]; y: km [m])"' in html
        and 'data-axes="x: t [s]; y: km [m]"' in html
        and "<figcaption>caption</figcaption>" in html
    )
    assert plt.get_fignums() == []  # the figure was closed


def test_a_plot_without_quantity_and_unit_on_an_axis_is_refused() -> None:
    """Every plot names each axis's quantity and unit; a shared x axis may leave it to the
    plot below; a figure refused is closed all the same."""
    plt = kit.pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    ax.set(xlabel="km", ylabel="offset [m]", title="Line 1")
    with pytest.raises(ValueError, match=r"plot 'Line 1': the x axis needs a label 'quantity \[unit\]', has 'km'"):
        kit.png(fig)
    fig, axes = plt.subplots(2, 1, sharex=True)
    for a in axes:
        a.plot([0, 1], [0, 1])
        a.set_ylabel("offset [m]")
    axes[1].set_xlabel("km [km]")
    assert kit.png(fig).axes == "y: offset [m]; x: km [km]"
    fig, ax = plt.subplots()
    ax.set_xlabel("t [s]")
    with pytest.raises(ValueError, match="the y axis"):
        kit.png(fig)
    assert plt.get_fignums() == []


def test_shares_are_percentages_and_columns_carry_labels() -> None:
    html = kit.frame_table(pd.DataFrame({"km_m": [20.0], "verified_share": [0.9934], "n_runs": [3]}))
    assert "<thead><tr><th>km [m]</th><th>verified share</th><th>runs</th></tr></thead>" in html
    assert [c for _, c in parse(html).cells] == ["20.000", "99.3 %", "3"]


def test_matplotlib_is_imported_lazily() -> None:
    code = (
        "import sys, dbtools.pagekit, fieldlogs.reports.page, fieldlogs.gisverify.page, fieldlogs.possession.page; "
        "print('matplotlib' in sys.modules)"
    )
    assert fresh_python(code).strip() == "False"


def test_kit_page_standard_in_the_browser(browser: Any, tmp_path: Path) -> None:
    """A kit page with a long table (its header stays in view while its rows scroll), a table
    far wider than 1,280 px (it scrolls in its box, the page does not) and a long unbroken
    path in a paragraph (it wraps): the standard of tests/pages.py holds."""
    plt = kit.pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 2])
    ax.set(xlabel="t [s]", ylabel="km [m]")
    long = pd.DataFrame({"km_m": np.arange(200) * 20.0, "gps_trusted_share": np.linspace(0, 1, 200)})
    wide = pd.DataFrame({f"figure_{k}_m": [123456.789 * k] for k in range(40)})
    html = kit.page(
        "kit",
        kit.paragraph("/data/" + "x" * 400 + "/run"),
        kit.frame_table(wide),
        kit.frame_table(long),
        kit.figure(kit.png(fig), "a plot"),
        verdict=kit.Verdict("Passed: 0 errors, 0 warnings", kit.Status.OK),
    )
    page = tmp_path / "kit.html"
    page.write_text(html, encoding="utf-8")
    assert check_page(browser, page, tmp_path / "shots", long_table=True) == {
        "verdict": "Passed: 0 errors, 0 warnings",
        "plots": 1,
        "long_table": True,
    }
    widest = browser.eval('Math.max(...[...document.querySelectorAll(".scroll")].map(b => b.scrollWidth))')
    assert widest > 1280  # the wide table is wider than the window, yet the page does not scroll sideways
