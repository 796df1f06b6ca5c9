"""``db review OLD NEW``: the page's content, its self-containment, and how it renders in a
real headless browser (Debian's chromium; skipped when it is not installed)."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.interchange.review import write_review
from dbtools.sample_network import sample_source_dir
from tests.cdp import Browser
from tests.dbtools.interchange.network_sources import SWITCH_IDS, TRACK_IDS, write_topology_sources
from tests.pages import check_page, open_page


@pytest.fixture(scope="module")
def change(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """OLD = the sample; NEW = one balise moved 12 m, one removed, one added, ten GIS points
    shifted about 3 m north, a feature's rows 5 m later."""
    root = tmp_path_factory.mktemp("review")
    src = root / "src"
    shutil.copytree(sample_source_dir(), src)
    b = pd.read_csv(src / "balises.csv", dtype=str, keep_default_na=False)
    i = b.index[b["balise_id"] == "0420-D-C003"][0]
    b.loc[i, ["km_actual_m", "km_equipment_m"]] = ["25567.0", "25579.0"]
    b.loc[i, "dist_from_initial_m"] = "1898.0"
    added = b[b["balise_id"] == "0420-D-C005"].copy()
    added["balise_id"], added["km_actual_m"], added["km_equipment_m"] = "0420-D-C099", "29500.0", "29500.0"
    added["dist_from_initial_m"] = "2559.0"
    b = pd.concat([b[b["balise_id"] != "0420-U-C004"], added])
    b.to_csv(src / "balises.csv", index=False)
    g = pd.read_csv(src / "gis.csv", dtype={"line_code": str})
    sel = (g["track"] == "D") & g["km_m"].between(20000, 20180)
    g.loc[sel, "lat"] += 2.7e-5
    g.to_csv(src / "gis.csv", index=False)
    f = pd.read_csv(src / "feature_points.csv", dtype={"line_code": str})
    f.loc[(f["feature_id"] == "F002") & (f["track"] == "D"), "km_m"] += 5.0
    f.to_csv(src / "feature_points.csv", index=False)
    old, new = root / "old.sqlite", root / "new.sqlite"
    build_db(sample_source_dir(), old, db_version="2026.10")
    build_db(src, new, db_version="2026.11")
    page = root / "review.html"
    r = CliRunner().invoke(app, ["db", "review", str(old), str(new), "--out", str(page)], env={"COLUMNS": "200"})
    assert r.exit_code in (0, 1), r.output
    return {"old": old, "new": new, "page": page, "root": root, "exit": Path(str(r.exit_code))}


def _payload(html: str) -> dict[str, Any]:
    """The map's data from the page (the JSON script the map script reads)."""
    m = re.search(r"<script type='application/json' id='review-map-data'>(.*?)</script>", html, re.S)
    assert m is not None, "the page has no map data"
    data: dict[str, Any] = json.loads(m.group(1))
    return data


def _outside_scripts(html: str) -> str:
    return re.sub(r"<(script|style)\b.*?</\1>", "", html, flags=re.S)


def test_page_sections_map_and_self_containment(change: dict[str, Path]) -> None:
    html = change["page"].read_text(encoding="utf-8")
    body = _outside_scripts(html.split("<body>", 1)[1])
    # self-contained: no external script, style sheet, image or link; nothing but inline code
    assert "http" not in body and "<link" not in html and "<script src" not in html.replace(" ", " ")
    assert re.search(r"<script[^>]*\bsrc=", html) is None
    assert "Leaflet 1.9.4, BSD-2-Clause" in html
    for text in ("Validation of NEW", "What changed", "Network map", "2026.10", "2026.11"):
        assert text in html
    assert "balise 0420-D-C003 (C, 0420 04 D) moved +12.0 m" in html
    assert "GIS 0420 D km 20k000–20k180: 10 points moved" in html
    data = _payload(html)
    kinds = [c["kind"] for c in data["changes"]]
    assert kinds.count("moved") == 1 + 10 + 6  # the balise, ten GIS points, six feature rows
    assert kinds.count("added") == 1 and kinds.count("removed") == 1
    moved = next(c for c in data["changes"] if c["what"] == "balise" and c["kind"] == "moved")
    assert moved["shift"] == pytest.approx(12.0)
    # a line-only DB: its implied line tracks, km ticks every km of both (16k000 … 30k000)
    assert sorted(t["id"] for t in data["tracks"]) == ["0420:D", "0420:U"]
    assert all(t["implied"] and t["kind"] == "main" for t in data["tracks"])
    assert sum(len(t["km"]) for t in data["ticks"]) == 2 * 15 and data["tiles"] is None
    assert data["switches"] == [] and data["connections"] == [] and data["groups"] == []


def test_existing_page_refused(change: dict[str, Path]) -> None:
    r = CliRunner().invoke(app, ["db", "review", str(change["old"]), str(change["new"]), "--out", str(change["page"])])
    assert r.exit_code == 3


@pytest.fixture(scope="module")
def topo_page(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """OLD = the sample (line only); NEW = the same with declared topology: tracks D1 D2 U1 U2,
    crossover X1 (track_points), switches W1 W2, their six connections, balise group 3:12."""
    root = tmp_path_factory.mktemp("review_topo")
    src = write_topology_sources(root / "src")
    old, new = root / "old.sqlite", root / "new.sqlite"
    build_db(sample_source_dir(), old, db_version="2026.10")
    build_db(src, new, db_version="2026.12")
    page = root / "review.html"
    write_review(old, new, page)
    return {"page": page, "root": root, "old": old, "new": new}


def test_topology_layers(topo_page: dict[str, Path]) -> None:
    html = topo_page["page"].read_text(encoding="utf-8")
    for line in (
        "track X1 (100.079 m, crossover) added",
        "switch W1 (point 1:9 at 0420 km 25k000.0) added",
        "connection D1 end ↔ X1 begin (both, switch W1) added",
        "2 balises added in balise group 3:12 (track D1): BG-3-12-0, BG-3-12-1",
    ):
        assert f"<li>{line}</li>" in html  # the diff summary of the network tables
    data = _payload(html)
    tracks = {t["id"]: t for t in data["tracks"]}
    assert sorted(tracks) == sorted(TRACK_IDS)  # declared tracks cover the line: no implied ones
    assert tracks["X1"]["kind"] == "crossover" and tracks["X1"]["line"] is None
    assert tracks["D1"]["km0"] == 16000.0 and tracks["D1"]["km1"] == 25000.0
    sw = {s["id"]: s for s in data["switches"]}
    assert sorted(sw) == list(SWITCH_IDS)
    assert (sw["W1"]["type"], sw["W1"]["n"], sw["W1"]["side"]) == ("point", 9.0, "right")
    assert sw["W2"]["side"] == "left" and sw["W1"]["ports"]["b2"] == "X1"
    # the switch sits at its toe: the end of D1, i.e. the first point of X1
    x1 = tracks["X1"]["c"]
    assert abs(sw["W1"]["lat"] * 1e6 - x1[0]) <= 1 and abs(sw["W1"]["lon"] * 1e6 - x1[1]) <= 1
    # three connections at each switch, all at the toe: one marker place per switch
    assert len(data["connections"]) == 2 and sorted(len(p["links"]) for p in data["connections"]) == [3, 3]
    (group,) = data["groups"]
    assert group["id"] == "3:12" and group["balises"] == ["BG-3-12-0", "BG-3-12-1"] and group["n_total"] == 2
    # ticks: D1 16..25, D2 25..30, U1 16..25, U2 26..30 (km 25k000 ends both D1 and D2); none on X1
    ticks = {t["track"]: t["km"] for t in data["ticks"]}
    assert {k: len(v) for k, v in ticks.items()} == {"D1": 10, "D2": 6, "U1": 10, "U2": 5}
    assert ticks["U2"][0] == 26000.0 and ticks["D2"][0] == 25000.0


def test_tiles_only_when_asked(topo_page: dict[str, Path]) -> None:
    out = topo_page["root"] / "tiles.html"
    url = "https://tile.example.org/{z}/{x}/{y}.png"
    r = CliRunner().invoke(
        app, ["db", "review", str(topo_page["old"]), str(topo_page["new"]), "--out", str(out), "--tiles", url]
    )
    assert r.exit_code in (0, 1), r.output
    data = _payload(out.read_text(encoding="utf-8"))
    assert data["tiles"] == url and data["tiles_attribution"] == "© OpenStreetMap contributors"
    assert _payload(topo_page["page"].read_text(encoding="utf-8"))["tiles"] is None


def test_page_renders_in_headless_chromium(change: dict[str, Path], browser: Browser) -> None:
    open_page(browser, change["page"])
    dom = browser.eval("document.documentElement.outerHTML")
    assert 'id="review-map"' in dom and 'data-ready="1"' in dom and "Validation of NEW" in dom
    assert "Legend" in dom and dom.count("leaflet-interactive") > 2  # the map script ran and drew


def test_page_standard_in_the_browser(change: dict[str, Path], browser: Browser, tmp_path: Path) -> None:
    """The rendering standard (tests/pages.py) on the review page: the verdict first, no
    sideways scroll at 1,280 px (the map included), sticky headers."""
    seen = check_page(browser, change["page"], tmp_path / "shots")
    assert re.fullmatch(r"(Passed|Failed): \d+ errors?, \d+ warnings? in NEW; content changed\.", seen["verdict"])


_POINT_ON = """(() => {{
  const p = [...document.querySelectorAll("{sel}")][{i}];
  const pt = p.getPointAtLength(p.getTotalLength() * {f}), m = p.getScreenCTM();
  return [pt.x * m.a + pt.y * m.c + m.e, pt.x * m.b + pt.y * m.d + m.f];
}})()"""
_CENTRE_OF = """(() => {{
  const r = [...document.querySelectorAll("{sel}")][{i}].getBoundingClientRect();
  return [r.x + r.width / 2, r.y + r.height / 2, r.width, r.height];
}})()"""
_TIPS = '[...document.querySelectorAll(".leaflet-tooltip")].map(e => e.textContent)'


def test_map_in_headless_chromium(topo_page: dict[str, Path], browser: Browser) -> None:
    """The real page in a real browser (CDP): loads with no console error and no request
    beyond itself, draws every track, switch, connection place, balise group and km tick,
    shows a track's id on hover and a switch's 1:n on hover after zooming in."""
    from PIL import Image

    b = browser  # the session's (tests/conftest.py)
    b.call("Network.enable")
    open_page(b, topo_page["page"])
    assert b.errors() == []
    assert b.requests() == [topo_page["page"].as_uri()]  # offline: nothing fetched
    assert b.eval('document.getElementById("review-map").dataset.ready') == "1"
    count = {s: b.eval(f'document.querySelectorAll("{s}").length') for s in ("path.track", "path.switch")}
    count |= {s: b.eval(f'document.querySelectorAll("{s}").length') for s in ("path.connection", "path.km-tick")}
    count["group"] = b.eval('document.querySelectorAll("path.balise-group").length')
    assert count == {"path.track": 5, "path.switch": 2, "path.connection": 2, "path.km-tick": 31, "group": 1}
    b.eval('document.getElementById("review-map").scrollIntoView()')
    x, y = b.eval(_POINT_ON.format(sel="path.track", i=0, f=0.3))
    b.mouse_move(x, y)
    tips = b.eval(_TIPS)
    assert len(tips) == 1 and tips[0][:2] in {"D1", "U1"}  # U1 is drawn over D1 (4 m apart)
    assert "line 0420 track" in tips[0] and "km 16k000.0" in tips[0]
    b.screenshot(topo_page["root"] / "map.png")
    # zoom in on W1 (wheel at the switch) until the crossover stands clear of the lines
    for _ in range(12):
        *_, w, h = b.eval(_CENTRE_OF.format(sel="path.kind-crossover", i=0))
        if max(w, h) > 300:  # 100 m of crossover
            break
        sx, sy, *_ = b.eval(_CENTRE_OF.format(sel="path.sw-point", i=0))
        b.call("Input.dispatchMouseEvent", type="mouseWheel", x=sx, y=sy, deltaX=0, deltaY=-60)
        b.eval("new Promise(r => setTimeout(r, 400))")
    assert 300 < max(w, h) < 1200, (w, h)
    sx, sy, *_ = b.eval(_CENTRE_OF.format(sel="path.sw-point", i=0))
    b.mouse_move(sx, sy)
    tips = b.eval(_TIPS)
    assert any("switch W" in t and "1:9" in t and "diverging" in t for t in tips), tips
    labels = b.eval('[...document.querySelectorAll(".sw-label")].map(e => e.textContent)')
    assert "W1 1:9 R" in labels  # close up, switches carry their label
    b.screenshot(topo_page["root"] / "map_zoomed.png")
    assert b.errors() == []
    img = Image.open(topo_page["root"] / "map_zoomed.png").convert("RGB")
    colours = img.getcolors(maxcolors=1 << 20) or []
    # the crossover's colour #b03a9e (anti-aliased: within 30 per channel)
    crossover = sum(n for n, c in colours if max(abs(a - b) for a, b in zip(c, (0xB0, 0x3A, 0x9E), strict=True)) < 30)
    assert crossover > 300
