"""Raw GNSS over the network sample (issue 31 item 2) [Yamamoto; S002]: the simulator's
pseudoranges along a network route, the fit constrained to each candidate track, and the
track_gnss aid deciding a facing switch on them.

Hand check of the residuals: D and U of line 0420 lie 4 m apart. On the wrong one the fit must
move each antenna 4 m across the track; the along-track position and the receiver clock absorb
the part of that shift which is common or along the track, the rest — 4 m · cos E · sin(A − ψ)
minus its mean, of the order of 4 m · 0.35 over a sky of 20-odd satellites — stays in the
residuals on top of the code noise and multipath left on the right track (0.7 m in open sky):
√(0.7² + 1.4²) ≈ 1.6 m, more than twice the right track's. Measured for seed 7: 0.71 m against
1.60 m over 364 receiver-epochs; the wrong track's test statistic exceeds the right one's at
every epoch, by 5.3 (median, both receivers) — under ``gnss.track_chi2`` = 10.83 per epoch, so
the line aid's rule would not call it far better, while the network rule (N = 5 epochs:
5 × 5.3 = 27 > 10.83) does."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.gnss.config import GnssConfig
from fieldlogs.gnss.ontrack import TrackEvidence, TrackSolutions
from fieldlogs.pipeline.aids.gnss import GnssUnit
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gnss import TrackGnssAid
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.runs.handle import Run, read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.enums import EventType
from tests.fieldlogs.pipeline.network_cases import MARGIN, Start, travel

pytestmark = pytest.mark.slow


def _raw_run(
    network: Network, folder: Path, tracks: list[str], points: list[list[object]], seed: int, **net: object
) -> Path:
    sc: dict[str, object] = {
        "name": "raw gnss on the network",
        "seed": seed,
        "sensors": {"gps": False},
        "slip": {"slips": 0, "slides": 0},
        "running": {"line_speed_kmh": 60.0},
        "network": {"tracks": tracks, "points": points, **net},
        "gnss_raw": {"enabled": True},
    }
    streams, meta = simulate_run(network, scenario_from_dict(sc, source="test"))
    write_run(folder, meta, streams, force=True)
    return folder


@pytest.fixture(scope="module")
def network(sample_network_db: Path) -> Network:
    return read_network(sample_network_db)


def test_raw_observables_along_a_network_route_with_a_tunnel(network: Network, tmp_path: Path) -> None:
    # U1 → 4 with a tunnel over 4's first 200 m: no epoch while the car centre is in it, and
    # epochs on either side (pseudoranges of both receivers, the run's vehicle block)
    tunnel = ["0420-4", 0.0, 200.0]
    folder = _raw_run(
        network,
        tmp_path / "t",
        ["0420-U1", "0420-4"],
        [["0420-U1", 4700.0], ["0420-4", 400.0]],
        3,
        gnss_outages=[tunnel],
    )
    run = read_run(folder)
    obs, truth = run.stream("gnss_obs"), run.stream("truth")
    assert obs is not None and truth is not None and run.meta is not None and run.meta.vehicle is not None
    assert set(obs["receiver"]) == {"rx1", "rx2"}
    at = np.searchsorted(truth["t"].to_numpy(dtype=float), obs["t"].to_numpy(dtype=float), side="right") - 1
    tid, pos = truth["track_id"].astype(str).to_numpy()[at], truth["pos_m"].to_numpy(dtype=float)[at]
    inside = (tid == "0420-4") & (pos > 1.0) & (pos < 199.0)
    assert not inside.any()
    assert ((tid == "0420-4") & (pos > 201.0)).any() and (tid == "0420-U1").any()


def test_the_wrong_parallel_track_leaves_large_residuals(network: Network, tmp_path: Path) -> None:
    folder = _raw_run(network, tmp_path / "d1", ["0420-D1"], [["0420-D1", 1500.0], ["0420-D1", 3500.0]], 7)
    unit = GnssUnit.for_run(read_run(folder), network, GnssConfig())
    right, wrong = unit.solutions("0420", "D", 1), unit.solutions("0420", "U", 1)
    assert isinstance(right, TrackSolutions) and isinstance(wrong, TrackSolutions)
    cols = ["receiver", "epoch", "residual_rms_m", "test", "ok"]
    m = right.table[cols].merge(wrong.table[cols], on=["receiver", "epoch"], suffixes=("", "_w"))
    m = m[m["ok"] & m["ok_w"]]
    assert len(m) >= 150
    rms, rms_w = float(m["residual_rms_m"].median()), float(m["residual_rms_m_w"].median())
    assert 0.5 < rms < 1.0 and rms_w > 2.0 * rms  # module docstring: 0.71 m against 1.60 m
    ev = TrackEvidence.between(wrong, right)  # U in force, D the other: U's excess over D
    cfg = GnssConfig()
    assert np.median(ev.excess) * cfg.split_epochs > cfg.track_chi2 and np.mean(ev.excess > 0) >= cfg.track_share
    args = (cfg.track_window_s, cfg.track_min_epochs, cfg.track_chi2, cfg.track_share)
    assert not any(TrackEvidence.between(right, wrong).far_better(float(t), *args) for t in ev.t)


LOOP = ["0420-U1", "0420-4", "0420-U3"]
"""U1 → facing switch W3 → station track 4 (520 m beside U2, no GIS grid: its track_points)."""


def _loop(network: Network, folder: Path, **net: object) -> tuple[Solution, pd.DataFrame, Run]:
    """The station loop's raw run (seed 11) replayed with the start, topology and track_gnss
    aids; its solution, truth and run; the determined cycles checked against the truth."""
    run = read_run(_raw_run(network, folder, LOOP, [["0420-U1", 4500.0], ["0420-U3", 100.0]], 11, **net))
    truth = run.stream("truth")
    assert truth is not None
    unit = GnssUnit.for_run(run, network, GnssConfig())
    km0 = float(truth["km_m"].iloc[0])
    k = 1 if float(truth["km_m"].iloc[-1]) > km0 else -1  # the F end leads
    tr = travel(network, truth["speed_mps"].to_numpy(dtype=float))
    lines = track_lines(network)
    aids = [
        Start("0420", "U", km0, k),
        TopologyAid(lines, MARGIN),
        TrackGnssAid(unit, unit.epoch_times(), lines, unit.cfg),
    ]
    sol = run_aids(tr, aids, MARGIN)  # type: ignore[arg-type]
    p = sol.positions
    at = np.searchsorted(truth["t"].to_numpy(dtype=float), p["t"].to_numpy(dtype=float), side="right") - 1
    true_track = truth["track_id"].astype(str).to_numpy()[at]
    det = (p["state"] == "determined").to_numpy()
    assert det.any() and (p["track_id"].astype(str).to_numpy()[det] == true_track[det]).all()
    return sol, truth, run


def test_track_gnss_resolves_the_station_loop_on_simulated_pseudoranges(network: Network, tmp_path: Path) -> None:
    sol, _, _ = _loop(network, tmp_path / "loop")
    res = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    assert len(res) == 1 and res[0].detail["evidence"] == "track_gnss"
    assert res[0].detail["track_id"] == "0420-4" and sorted(res[0].detail["candidates"]) == ["0420-4", "0420-U2"]


def test_track_gnss_stays_fail_safe_under_multipath_at_the_neighbouring_track(network: Network, tmp_path: Path) -> None:
    """The station loop as above with ``network.multipath`` over the whole route: a reflecting
    surface at the neighbouring track (U2 beside loop 4, the other main track beside U1/U3),
    amplitude 0.5 (fieldlogs.simulate.gnss.reflection); the pseudoranges of the satellites
    across from it carry the two-path errors, metres of either sign held over seconds. No cycle
    is determined on a wrong track (``_loop``), whichever evidence resolves the loop."""
    _, _, run = _loop(network, tmp_path / "mp", multipath=[[t, 0.0, 1.0e5, 2.5] for t in LOOP])
    assert run.meta is not None
    refl = run.meta.extra["sim_truth"]["gnss_raw"]["reflection"]
    assert refl["observations"] > 100 and refl["code_min_m"] < -2.0
