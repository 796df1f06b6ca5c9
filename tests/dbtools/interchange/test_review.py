"""``db review OLD NEW``: the page's content, its self-containment, and how it renders in a
real headless browser (Debian's chromium; skipped when it is not installed)."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.sample_network import sample_source_dir


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


def test_page_sections_map_and_self_containment(change: dict[str, Path]) -> None:
    html = change["page"].read_text(encoding="utf-8")
    body = html.split("<body>", 1)[1]
    assert "<script" not in html and "http" not in body.replace("http://www.w3.org/2000/svg", "")
    for text in ("Validation of NEW", "What changed", "Map of the changes", "2026.10", "2026.11"):
        assert text in html
    assert "balise 0420-D-C003 (C, 0420 04 D) moved +12.0 m" in html
    assert "GIS 0420 D km 20k000–20k180: 10 points moved" in html
    assert html.count("class='chg moved'") == 1 + 10 + 6  # the balise, ten GIS points, six feature rows
    assert html.count("class='chg added'") == 1 and html.count("class='chg removed'") == 1
    assert "arrows ×" in html and "Legend" in html


def test_existing_page_refused(change: dict[str, Path]) -> None:
    r = CliRunner().invoke(app, ["db", "review", str(change["old"]), str(change["new"]), "--out", str(change["page"])])
    assert r.exit_code == 3


def _chromium() -> str | None:
    return shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)


def _browser(exe: str, page: Path, *args: str) -> subprocess.CompletedProcess[bytes]:
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run(
            [
                exe,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--no-first-run",
                f"--user-data-dir={profile}",
                *args,
                page.as_uri(),
            ],
            capture_output=True,
            timeout=90,
            check=False,
        )


@pytest.mark.skipif(_chromium() is None, reason="chromium is not installed (.ci/run installs it)")
def test_page_renders_in_headless_chromium(change: dict[str, Path]) -> None:
    from PIL import Image

    exe = _chromium()
    assert exe is not None
    dom = _browser(exe, change["page"], "--dump-dom").stdout.decode("utf-8", "replace")
    assert 'id="review-map"' in dom and "Legend" in dom and "Validation of NEW" in dom
    png = change["root"] / "review.png"
    _browser(exe, change["page"], f"--screenshot={png}", "--window-size=1200,1800")
    assert png.is_file(), "chromium wrote no screenshot"
    img = Image.open(png).convert("RGB")
    colours = img.getcolors(maxcolors=1 << 20) or []
    assert len(colours) > 50  # not blank: text, tables and the map
    orange = sum(n for n, (r, g, b) in colours if r > 190 and 90 < g < 140 and b < 40)
    grey_track = sum(n for n, c in colours if c == (0x9A, 0xA0, 0xA6))
    assert orange > 20 and grey_track > 200  # the arrows and the track lines were drawn
