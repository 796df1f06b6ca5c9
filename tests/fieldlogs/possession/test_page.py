"""The possession HTML page: the legend is every alarm and notice type with its meaning,
alarms are marked, the timeline is an embedded PNG."""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

from fieldlogs.possession.page import render_html
from fieldlogs.simulate.possession import make_case
from schemas.enums import ALARM_MEANING, AlarmType, NoticeType
from tests.fieldlogs.possession.test_possession import NET, check_case
from tests.pages import check_page


def test_page_legend_alarms_and_timeline() -> None:
    case = make_case(NET, "overrun", 31)
    chk = check_case(case)
    text = render_html([chk], plan="plan <1>.csv", db="net.sqlite")
    for typ in (*AlarmType, *NoticeType):
        assert f"<dt>{typ.value}</dt><dd>{html.escape(ALARM_MEANING[typ])}</dd>" in text
    assert [a.type for a in chk.alarms] == [AlarmType.OVERRUN]
    assert '<td class="alarm">overrun</td>' in text and "<span class='badge alarm'>1 alarm(s)</span>" in text
    assert "<code>plan &lt;1&gt;.csv</code>" in text and text.count("data:image/png;base64,") == 1
    assert "<script" not in text and "http" not in text.split("<body>")[1]


def test_page_standard_in_the_browser(browser: Any, tmp_path: Path) -> None:
    """The rendering standard (tests/pages.py) on a possession page: verdict first, no sideways
    scroll, sticky headers, the timeline's axes named with units."""
    checks = [check_case(make_case(NET, kind, 31)) for kind in ("overrun", "wrong_track")]
    page = tmp_path / "possession.html"
    page.write_text(render_html(checks, plan="plan.csv", db="net.sqlite"), encoding="utf-8")
    seen = check_page(browser, page, tmp_path / "shots")
    assert seen["verdict"].startswith("Alarm: ") and seen["plots"] == 2
