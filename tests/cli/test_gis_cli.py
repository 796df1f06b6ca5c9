"""``trainpos gis grid`` through the CLI: output, messages and exit codes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from typer.testing import CliRunner

from cli.main import app
from dbtools.gis.geometry import GEOD

LON0, LAT0 = 139.4, 35.9
LON1 = float(GEOD.fwd(LON0, LAT0, 90.0, 1000.0)[0])


def survey(folder: Path, post_km: tuple[str, str] = ("0k000", "1k000")) -> tuple[Path, Path]:
    """A straight east-west track, 1 km, posts at both ends."""
    folder.mkdir(parents=True, exist_ok=True)
    cl, kp = folder / "centrelines.csv", folder / "kmposts.csv"
    pd.DataFrame({"line_code": "0420", "track": "D", "seq": [1, 2], "lon": [LON0, LON1], "lat": LAT0}).to_csv(
        cl, index=False
    )
    pd.DataFrame({"line_code": "0420", "km_m": list(post_km), "lon": [LON0, LON1], "lat": LAT0}).to_csv(kp, index=False)
    return cl, kp


def grid(runner: CliRunner, cl: Path, kp: Path, out: Path, *extra: str):  # type: ignore[no-untyped-def]
    args = ["gis", "grid", str(cl), "--posts", str(kp), "--out", str(out), *extra]
    return runner.invoke(app, args, env={"COLUMNS": "250"})


def test_grid_ok_then_refuses_then_forces(runner: CliRunner, tmp_path: Path) -> None:
    cl, kp = survey(tmp_path / "survey")
    out = tmp_path / "src" / "gis.csv"
    r = grid(runner, cl, kp, out)
    assert r.exit_code == 0, r.output
    assert "51" in r.output and str(out) in r.output
    g = pd.read_csv(out, dtype={"line_code": str})
    np.testing.assert_array_equal(g["km_m"], np.arange(0.0, 1001.0, 20.0))
    r = grid(runner, cl, kp, out)
    assert r.exit_code == 3 and "use --force" in r.output
    assert grid(runner, cl, kp, out, "--force").exit_code == 0


def test_bad_input_exits_1_with_findings(runner: CliRunner, tmp_path: Path) -> None:
    cl, kp = survey(tmp_path / "survey", post_km=("0k000", "1k0x0"))
    r = grid(runner, cl, kp, tmp_path / "gis.csv")
    assert r.exit_code == 1
    assert "schema.type" in r.output and "km_m" in r.output and "nothing was written" in r.output
    assert not (tmp_path / "gis.csv").exists()


def test_missing_input_exits_2(runner: CliRunner, tmp_path: Path) -> None:
    _, kp = survey(tmp_path / "survey")
    r = grid(runner, tmp_path / "none.csv", kp, tmp_path / "gis.csv")
    assert r.exit_code == 2 and "no such file" in r.output


def test_help_has_an_example(runner: CliRunner) -> None:
    r = runner.invoke(app, ["gis", "grid", "--help"])
    assert r.exit_code == 0 and "Example:" in r.output
