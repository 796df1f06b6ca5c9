"""The rendering standard of the suite's HTML pages, checked in a real headless browser
(issue 33 item 4; :mod:`dbtools.pagekit`): one Chromium per test session (the ``browser``
fixture of tests/conftest.py), each page kind's test loading its page at 1,280 × 800.

:func:`check_page` asserts, and saves a screenshot:

* the page loads with no console error;
* it never scrolls sideways (``scrollWidth ≤ clientWidth`` of the document);
* its first text under the heading is the plain-language verdict (``Passed: …``);
* every table header is sticky, and the longest table's header stays in view when its rows
  are scrolled to the end (when the table is taller than its box);
* every plot names the quantity and unit of each axis (``data-axes``: ``x: t [s]; y: km [m]``).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from tests.cdp import Browser

WIDTH, HEIGHT = 1280, 800

_VERDICT = """(() => {
  const h1 = document.querySelector("h1"), v = h1 && h1.nextElementSibling;
  const text = document.body.innerText.trim();
  return {h1: h1 && h1.innerText, id: v && v.id, verdict: v && v.innerText, text: text.slice(0, 400)};
})()"""

_OVERFLOW = """(() => {
  const d = document.documentElement;
  return [d.scrollWidth, d.clientWidth];
})()"""

_STICKY = """(() => [...document.querySelectorAll("thead th")].every(
  th => getComputedStyle(th).position === "sticky"))()"""

_SCROLL_LONGEST = """(() => {
  const boxes = [...document.querySelectorAll(".scroll")].filter(b => b.querySelector("thead"));
  if (!boxes.length) return null;
  const box = boxes.reduce((a, b) => (b.scrollHeight > a.scrollHeight ? b : a));
  if (box.scrollHeight <= box.clientHeight + 1) return {long: false, rows: box.querySelectorAll("tbody tr").length};
  box.scrollIntoView();
  box.scrollTop = box.scrollHeight;
  const th = box.querySelector("thead th"), b = box.getBoundingClientRect(), h = th.getBoundingClientRect();
  const hit = document.elementFromPoint(h.x + h.width / 2, h.y + h.height / 2);
  const last = [...box.querySelectorAll("tbody tr")].pop().getBoundingClientRect();
  return {long: true, boxTop: b.top, thTop: h.top, onTop: th.contains(hit), scrolled: box.scrollTop,
          lastVisible: last.bottom <= b.bottom + 1 && last.top >= b.top};
})()"""

_PLOTS = """[...document.querySelectorAll("figure img")].map(i => ({
  axes: i.dataset.axes, alt: i.alt, loaded: i.complete && i.naturalWidth > 0,
  right: i.getBoundingClientRect().right, inside: document.documentElement.clientWidth}))"""

#: One axis label as the page states it: a quantity, then its unit in brackets.
AXIS = re.compile(r"[xy]: \S.*\[[^\]]+\].*")


def open_page(browser: Browser, page: Path) -> None:
    """``page`` in the session's browser at 1,280 × 800, the events of earlier pages forgotten."""
    browser.events.clear()
    browser.call("Emulation.setDeviceMetricsOverride", width=WIDTH, height=HEIGHT, deviceScaleFactor=1, mobile=False)
    browser.load(page.as_uri())


def check_page(browser: Browser, page: Path, shots: Path, *, long_table: bool = False) -> dict[str, Any]:
    """Assert the rendering standard on ``page`` (see the module), save ``shots``/NAME.png
    (the top of the page) and NAME-scrolled.png (the longest table scrolled to its end);
    ``long_table``: the page must have a table taller than its box (the sticky header is
    then seen to stay). Returns what was measured."""
    open_page(browser, page)
    assert browser.errors() == [], browser.errors()
    scroll_width, client_width = browser.eval(_OVERFLOW)
    assert scroll_width <= client_width, f"{page.name}: the page scrolls sideways ({scroll_width} > {client_width})"
    v = browser.eval(_VERDICT)
    assert v["id"] == "verdict", f"{page.name}: the heading is not followed by the verdict: {v}"
    assert v["text"].startswith(f"{v['h1']}\n") and v["text"][len(v["h1"]) :].lstrip().startswith(v["verdict"]), v
    assert re.match(r"[A-Z][A-Za-z ]+: \S", v["verdict"]), f"not a plain verdict: {v['verdict']!r}"
    shots.mkdir(parents=True, exist_ok=True)
    browser.screenshot(shots / f"{page.stem}.png")
    assert browser.eval(_STICKY), f"{page.name}: a table header is not sticky"
    plots = browser.eval(_PLOTS)
    for p in plots:
        labels = [a.strip() for a in (p["axes"] or "").split(";")]
        assert p["loaded"] and p["right"] <= p["inside"], (page.name, p)
        assert {a[0] for a in labels if a} == {"x", "y"}, f"{page.name}: a plot lacks an axis label: {p['alt']!r}"
        assert all(AXIS.fullmatch(a) for a in labels), f"{page.name}: axis without quantity [unit]: {labels}"
    longest = browser.eval(_SCROLL_LONGEST)
    if long_table:
        assert longest is not None and longest["long"], f"{page.name}: no table taller than its box: {longest}"
    if longest and longest["long"]:
        assert longest["scrolled"] > 0 and longest["lastVisible"], longest
        assert abs(longest["thTop"] - longest["boxTop"]) <= 2 and longest["onTop"], f"header not in view: {longest}"
        browser.screenshot(shots / f"{page.stem}-scrolled.png")
    scroll_width, client_width = browser.eval(_OVERFLOW)
    assert scroll_width <= client_width
    return {"verdict": v["verdict"], "plots": len(plots), "long_table": bool(longest and longest["long"])}
