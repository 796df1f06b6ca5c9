"""A run replayed with another network's DB is refused (issue 32 item 11): it exited 0 with
"route —, first determined never" and no word."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.gis.geometry import Projector
from dbtools.sources import write_source_set
from fieldlogs.quality.dbfit import MIN_FIXES, db_fit_findings
from fieldlogs.runs.handle import Run
from fieldlogs.simulate.networks.synthetic import build_network, demo_line

SAMPLES = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs"


@pytest.fixture(scope="module")
def swiss_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A double-track line near Bern (UTM 32N): another network than the Japanese sample's."""
    work = tmp_path_factory.mktemp("swiss")
    src = write_source_set(
        build_network([demo_line(x0=380_000.0, y0=5_200_000.0)], Projector.from_epsg(32632)), work / "src"
    )
    build_db(src, work / "ch.sqlite")
    return work / "ch.sqlite"


@pytest.mark.parametrize("run", ["sim-d-slips", "sim-u-tunnel", "sim-road-rail"])
def test_a_run_on_another_network_is_refused(run: str, swiss_db: Path, tmp_path: Path) -> None:
    r = CliRunner().invoke(app, ["run", str(SAMPLES / run), "--db", str(swiss_db), "--out", str(tmp_path / "o")])
    assert r.exit_code == 1, r.output
    assert "run.db_mismatch" in r.output and "not on this DB's network" in r.output.replace("\n", " ")
    assert not (tmp_path / "o").exists()


def test_a_run_on_its_own_network_fits(sample_db: Path) -> None:
    from dbtools.database import read_network

    assert db_fit_findings(Run(SAMPLES / "sim-d-slips"), read_network(sample_db)) == []


def test_some_fixes_in_the_area_keep_the_run(swiss_db: Path, tmp_path: Path) -> None:
    """One side fitting is enough: a run whose GPS fixes are all in the area but whose
    telegrams name foreign lines is logs check's business (warnings), not a refusal."""
    from dbtools.database import read_network

    net = read_network(swiss_db)
    run = tmp_path / "run"
    shutil.copytree(SAMPLES / "sim-d-slips", run)
    gps = pd.read_parquet(run / "gps.parquet")
    g = net.gis.iloc[: len(gps)]
    gps["lat"] = g["lat"].to_numpy()[: len(gps)] if len(g) >= len(gps) else float(g["lat"].iloc[0])
    gps["lon"] = g["lon"].to_numpy()[: len(gps)] if len(g) >= len(gps) else float(g["lon"].iloc[0])
    gps.to_parquet(run / "gps.parquet", index=False)
    assert db_fit_findings(Run(run), net) == []


def test_too_few_fixes_cannot_tell(swiss_db: Path, tmp_path: Path) -> None:
    from dbtools.database import read_network

    run = tmp_path / "run"
    shutil.copytree(SAMPLES / "sim-d-slips", run)
    (run / "balise.parquet").unlink()
    gps = pd.read_parquet(run / "gps.parquet")
    gps.iloc[: MIN_FIXES - 1].to_parquet(run / "gps.parquet", index=False)
    meta = json.loads((run / "run.json").read_text())
    (run / "run.json").write_text(json.dumps(meta))
    assert db_fit_findings(Run(run), read_network(swiss_db)) == []
