"""GIS verification per track off a line (``track_points``): the sim-net sample runs on
station tracks and a crossover of the sample network, and a hand-shifted track."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.gis.verify.config import VerifyConfig
from dbtools.gis.verify.track_points import verify_track_points
from dbtools.network import Network
from fieldlogs.gisverify.evidence import collect_evidence, verify_runs

SAMPLE_LOGS = Path(__file__).parents[3] / "fieldlogs" / "sample_logs"
RUNS = ("crossover", "turnback", "station")


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("tp-logs")
    for r in RUNS:
        shutil.copytree(SAMPLE_LOGS / f"sim-net-{r}", root / f"sim-net-{r}")
    return root


def test_fixes_on_station_tracks_and_crossovers_are_verified_per_track(sample_network_db: Path, logs: Path) -> None:
    rep = verify_runs(sample_network_db, [logs], workers=1)
    tp = rep.track_points
    assert tp is not None
    cov = tp.coverage.set_index("track_id")
    assert set(cov.index) == {"0420-3", "0420-4", "0420-X1", "0420-X2"}
    # the turnback runs onto station track 4 and back, the crossover run over X1; the station
    # run's track 3 is under a roof (few trusted fixes)
    assert cov.loc["0420-4", "fixes"] > 100 and cov.loc["0420-X1", "fixes"] >= 1 and cov.loc["0420-X2", "fixes"] == 0
    # the simulator's GNSS sits on the true centreline: sub-metre mean offsets, no defect from one run
    assert tp.cells["offset_mean_m"].abs().max() < 2.0 and tp.defects.empty
    # the line verification leaves those fixes to the track-point grid (its unknown tracks)
    assert rep.verification.counts["fixes_unknown_track"] == tp.counts["fixes_in"] == tp.counts["fixes_matched"]
    assert "track_points" in rep.to_dict() and tp.km_residual.get("n", 0) in (0, None)


def _shifted(net: Network, track_id: str, metres: float) -> Network:
    """``track_id``'s track points moved ``metres`` to the left of its begin → end chord."""
    tp = net.track_points.copy()
    on = tp["track_id"] == track_id
    lat, lon = tp.loc[on, "lat"].to_numpy(), tp.loc[on, "lon"].to_numpy()
    k = np.cos(np.radians(lat.mean()))
    de, dn = (lon[-1] - lon[0]) * 111_320.0 * k, (lat[-1] - lat[0]) * 111_320.0
    ue, un = -dn / np.hypot(de, dn), de / np.hypot(de, dn)  # left normal
    tp.loc[on, "lat"] = lat + metres * un / 111_320.0
    tp.loc[on, "lon"] = lon + metres * ue / (111_320.0 * k)
    return Network(tables={**net.tables, "track_points": tp}, meta=dict(net.meta), origin=net.origin)


def test_a_shifted_station_track_shows_the_shift(sample_network_db: Path, logs: Path) -> None:
    """Track 4's grid moved 3 m left: the fixes on it lie 3 m right of it (offset −3 m ± GPS noise)."""
    net = read_network(sample_network_db)
    ev = collect_evidence([logs / "sim-net-turnback"], sample_network_db, network=net, workers=1)
    cfg = VerifyConfig()  # one run: every cell unverified, but each has its mean offset
    base = verify_track_points(net, ev.fixes, cfg)
    moved = verify_track_points(_shifted(net, "0420-4", 3.0), ev.fixes, cfg)
    assert base is not None and moved is not None
    b = base.cells[base.cells["track_id"] == "0420-4"].set_index("pos_from_m")["offset_mean_m"]
    m = moved.cells[moved.cells["track_id"] == "0420-4"].set_index("pos_from_m")["offset_mean_m"]
    common = b.index.intersection(m.index)
    assert len(common) >= 10
    diff = (m[common] - b[common]).to_numpy()
    assert np.abs(np.abs(diff) - 3.0).max() < 0.3  # the whole 3 m shift, on every cell
    assert len(set(np.sign(diff))) == 1  # to one side


def test_no_track_points_no_track_point_verification(sample_network_db: Path) -> None:
    net = read_network(sample_network_db)
    empty = Network(tables={**net.tables, "track_points": net.track_points.iloc[:0]}, meta=dict(net.meta))
    assert verify_track_points(empty, pd.DataFrame({"track_id": []})) is None
