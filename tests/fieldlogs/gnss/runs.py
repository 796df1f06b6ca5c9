"""Simulated runs with raw GNSS (``[gnss_raw]``) on the sample network, for the GNSS tests."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from dbtools.network import Network
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run


def gnss_scenario(network: Network, track: str = "D", length_m: float = 4000.0, **over: Any) -> dict[str, Any]:
    """A run of ``length_m`` on ``track`` of the sample line in its normal direction, raw GNSS on."""
    g = network.gis
    line = sorted(set(g["line_code"].astype(str)))[0]
    km = g.loc[(g["line_code"] == line) & (g["track"] == track), "km_m"]
    lo, hi = float(km.min()) + 300.0, float(km.max()) - 300.0
    path = [lo, lo + length_m] if track == "D" else [hi, hi - length_m]
    sc: dict[str, Any] = {
        "name": "gnss test",
        "route": {"line_code": line, "track": track, "path_km_m": path},
        "slip": {"slips": 1, "slides": 1},
        "gnss_raw": {"enabled": True},
    }
    for key, value in over.items():
        sc[key] = {**sc.get(key, {}), **value} if isinstance(value, dict) else value
    return sc


def simulate_gnss_run(network: Network, folder: Path, seed: int = 11, **over: Any) -> Path:
    streams, meta = simulate_run(network, scenario_from_dict(gnss_scenario(network, **over)), seed=seed)
    return write_run(folder, meta, streams, force=True)
