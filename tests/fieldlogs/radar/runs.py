"""Seeded radar runs for tests and ``bench/bench_radar.py``: the paper's two experiments
(accelerating from standstill, Fig. 2; under an overpass without GNSS, Fig. 3) and
variations (slab track, reversed cab, radar looking backward, vibration, lower SNR).

Every run starts and ends at rest (standstill frames), reaches a seeded top speed and is
short (tens of seconds: IF data is 10 kHz × 4 columns).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.runs.meta import RunMeta
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.radar import RadarParams

KINDS = ("accelerate", "overpass", "slab", "reverse")
ACCEL_KMH_S, BRAKE_KMH_S = 2.5, 3.0


def _route(network: Network, track: str) -> tuple[str, float, float]:
    gis = network.gis
    line = sorted(set(gis["line_code"].astype(str)))[0]
    km = gis.loc[(gis["line_code"] == line) & (gis["track"] == track), "km_m"].astype(float)
    return line, float(km.min()) + 300.0, float(km.max()) - 300.0


def radar_scenario(i: int, network: Network, *, top_kmh: float | None = None) -> dict[str, Any]:
    """Scenario overrides of run ``i``: kind ``KINDS[i % 4]``, top speed 30–100 km/h."""
    rng = np.random.default_rng(500 + i)
    kind = KINDS[i % len(KINDS)]
    track = "D" if i % 2 == 0 else "U"
    v = float(rng.uniform(30.0, 100.0)) if top_kmh is None else top_kmh
    line, lo, hi = _route(network, track)
    vm = v / 3.6
    cruise_s = 6.0
    length = vm * vm / (2 * ACCEL_KMH_S / 3.6) + vm * vm / (2 * BRAKE_KMH_S / 3.6) + vm * cruise_s + 40.0
    start = lo + float(rng.uniform(0.0, 2000.0))
    path = [start, start + length] if track == "D" else [hi - (start - lo), hi - (start - lo) - length]
    radar_if: dict[str, Any] = {"snr_db": float(rng.uniform(25.0, 35.0))}
    sc: dict[str, Any] = {
        "name": f"radar-{kind}-{i}",
        "run": {"run_id": f"RADAR-{i:03d}"},
        "route": {"line_code": line, "track": track, "path_km_m": path, "start_cab": "F"},
        "running": {
            "line_speed_kmh": v,
            "accel_kmh_s": ACCEL_KMH_S,
            "brake_kmh_s": BRAKE_KMH_S,
            "stop_at_stations": False,
            "standstill_start_s": 8.0,
            "standstill_end_s": 7.0,
        },
        "slip": {"slips": 0, "slides": 0, "on_grade_curve": False},
        "sensors": {"radar_if": True, "balise": False},
        "radar_if": radar_if,
    }
    mid = 0.5 * (path[0] + path[1])
    if kind == "overpass":
        sc["gps"] = {"outages_km_m": [[mid - 20.0, mid + 20.0]]}
    elif kind == "slab":
        radar_if["slab_km_m"] = [[min(path) + 0.2 * length, min(path) + 0.8 * length]]
        radar_if["vibration_mm"] = 0.3
    elif kind == "reverse":
        sc["route"]["start_cab"] = "R"
        radar_if["looks_toward"] = "R" if i % 8 == 3 else "F"
    return sc


def simulate_radar_run(i: int, network: Network, **kw: Any) -> tuple[dict[str, pd.DataFrame], RunMeta]:
    """Streams and run.json metadata of run ``i`` (seed 7000 + i)."""
    return simulate_run(network, scenario_from_dict(radar_scenario(i, network, **kw), f"radar-{i}"), seed=7000 + i)


def radar_of(meta: RunMeta) -> RadarParams:
    return RadarParams(**meta.extra["radar"])


def truth_at(truth: pd.DataFrame, t: np.ndarray) -> np.ndarray:
    """True signed speed (+ toward F) at times ``t``, linear between the 10 Hz samples."""
    return np.asarray(np.interp(t, truth["t"].to_numpy(dtype=float), truth["speed_mps"].to_numpy(dtype=float)))


def onset_time(truth: pd.DataFrame, kmh: float = 0.5) -> float:
    """First time the true speed exceeds ``kmh`` (the vehicle is moving)."""
    v = np.abs(truth["speed_mps"].to_numpy(dtype=float))
    k = int(np.argmax(v > kmh / 3.6))
    return float(truth["t"].to_numpy(dtype=float)[k])
