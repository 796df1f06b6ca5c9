"""``trainpos radar speed``: formats, outputs, refusals, plot, and runs it cannot process."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
from typer.testing import CliRunner

from cli.main import app
from schemas.outputs import RADAR_SPEED


def invoke(*args: object) -> object:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


def test_table_csv_json(radar_run: Path, tmp_path: Path) -> None:
    res = invoke("radar", "speed", radar_run)
    assert res.exit_code == 0, res.output  # type: ignore[attr-defined]
    assert "standstill" in res.output and "112.14 km/h" in res.output  # type: ignore[attr-defined]
    out = tmp_path / "speed.csv"
    res = invoke("radar", "speed", radar_run, "--format", "csv", "--out", out)
    assert res.exit_code == 0, res.output  # type: ignore[attr-defined]
    frame = pd.read_csv(out)
    assert list(frame.columns) == RADAR_SPEED.column_names
    assert {"ok", "standstill"} <= set(frame["status"])
    assert frame.loc[frame["status"] == "ok", "speed_mps"].abs().max() > 25 / 3.6 * 0.95
    res = invoke("radar", "speed", radar_run, "--format", "json")
    doc = json.loads(res.output)  # type: ignore[attr-defined]
    assert doc["radar"]["t_epi_s"] == 0.307 and len(doc["frames"]) == len(frame)
    assert doc["summary"]["status"]["ok"] == int((frame["status"] == "ok").sum())
    assert doc["frames"][0]["speed_mps"] == 0.0 and doc["frames"][0]["snr_db"] is None


def test_existing_output_refused_without_force(radar_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "speed.json"
    out.write_text("keep", encoding="utf-8")
    res = invoke("radar", "speed", radar_run, "--format", "json", "--out", out)
    assert res.exit_code == 3 and out.read_text(encoding="utf-8") == "keep"  # type: ignore[attr-defined]
    res = invoke("radar", "speed", radar_run, "--format", "json", "--out", out, "--force")
    assert res.exit_code == 0 and json.loads(out.read_text(encoding="utf-8"))["frames"]  # type: ignore[attr-defined]
    res = invoke("radar", "speed", radar_run, "--out", tmp_path / "x.txt")
    assert res.exit_code == 2 and "--format csv" in res.output  # type: ignore[attr-defined]


def test_plot_png(radar_run: Path, tmp_path: Path) -> None:
    png = tmp_path / "radar.png"
    res = invoke(
        "radar", "speed", radar_run, "--format", "csv", "--out", tmp_path / "s.csv", "--plot", png, "--plot-t", 20
    )
    assert res.exit_code == 0, res.output  # type: ignore[attr-defined]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_runs_it_cannot_process(radar_run: Path, tmp_path: Path) -> None:
    bare = tmp_path / "bare"
    shutil.copytree(radar_run, bare)
    (bare / "radar_if.parquet").unlink()
    res = invoke("radar", "speed", bare)
    assert res.exit_code == 2 and "no radar_if stream" in res.output  # type: ignore[attr-defined]
    broken = tmp_path / "broken"
    shutil.copytree(radar_run, broken)
    meta = json.loads((broken / "run.json").read_text(encoding="utf-8"))
    meta["radar"]["t_pri_s"] = "fast"
    (broken / "run.json").write_text(json.dumps(meta), encoding="utf-8")
    res = invoke("radar", "speed", broken)
    assert res.exit_code == 2 and "radar.t_pri_s" in res.output and "Traceback" not in res.output  # type: ignore[attr-defined]
