"""The paper's two experiments as simulator scenarios [S004 Fig. 2, Fig. 3]
(``fieldlogs/simulate/scenarios/radar_fig*.toml``, README's radar examples): they load, and
their motion and GNSS do what the figures need (the IF samples are left off here: their
processing is tested on ``runs.py``'s runs)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.database import read_network
from fieldlogs.simulate.scenario import Scenario, load_scenario
from fieldlogs.simulate.simulator import simulate_run

SCENARIOS = Path(__file__).resolve().parents[3] / "fieldlogs" / "simulate" / "scenarios"


def _motion(sample_db: Path, name: str) -> tuple[Scenario, dict[str, pd.DataFrame]]:
    sc = load_scenario(SCENARIOS / name)
    assert sc.sensors.radar_if  # the scenario is a radar experiment
    quick = replace(sc, sensors=replace(sc.sensors, radar_if=False))
    return sc, simulate_run(read_network(sample_db), quick, seed=1).streams


def test_fig2_accelerates_from_standstill(sample_db: Path) -> None:
    sc, s = _motion(sample_db, "radar_fig2_standstill.toml")
    truth = s["truth"]
    t, v = truth["t"].to_numpy(), truth["speed_mps"].to_numpy()
    moving = t[np.abs(v) > 0.01]
    # at rest first (the jerk limit's centred smoothing starts the move up to half its ~5 s
    # window before standstill_start_s): many 307 ms frames without Doppler …
    assert moving[0] >= sc.running.standstill_start_s - 3.0
    assert np.abs(v).max() * 3.6 > 0.95 * sc.running.line_speed_kmh  # … up to 40 km/h …
    assert np.abs(v[-5:]).max() < 0.01  # … and to a stop again


def test_fig3_passes_under_an_overpass_without_gnss(sample_db: Path) -> None:
    sc, s = _motion(sample_db, "radar_fig3_overpass.toml")
    truth, gps = s["truth"], s["gps"]
    ((lo, hi),) = sc.gps.outages_km_m
    km_at_fix = np.interp(gps["t"], truth["t"], truth["km_m"])
    under = (km_at_fix >= lo) & (km_at_fix <= hi)
    assert under.sum() >= 2 and (gps.loc[under, "fix"] == 0).all()  # GNSS lost under the deck
    assert (gps.loc[km_at_fix < lo - 50.0, "fix"] > 0).mean() > 0.9
    speed_under = np.interp(gps.loc[under, "t"], truth["t"], truth["speed_mps"]) * 3.6
    assert np.allclose(np.abs(speed_under), sc.running.line_speed_kmh, atol=1.0)  # at 45 km/h
    ((slab_lo, slab_hi),) = sc.radar_if.slab_km_m
    assert slab_lo <= lo and hi <= slab_hi  # slab track bed under the overpass
