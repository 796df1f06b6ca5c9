"""Bundled sample runs over the sample network's station, crossovers and junction
(:mod:`fieldlogs.simulate.networks.sample_junctions`), routed by the ``[network]`` scenario table:

* ``sim-net-crossover`` — an up train (km decreasing) crosses from U to D on crossover X1 and
  runs on down the D track (U → crossover → D);
* ``sim-net-station`` — a down train arrives on loop track 3 of the four-track station, stops
  under its roof (no GNSS over 250 m of track 3) and departs back onto D; multipath pulls its
  GPS fixes 2.5 m toward the U track over 1 km before the station;
* ``sim-net-junction`` — a down train takes the branch line 0421 at the 1:12 junction, with a
  300 m tunnel on the branch;
* ``sim-net-turnback`` — an up train arrives on loop track 4, changes ends and runs back; it
  records the R cab's own sensors too (``[cab_r]``: ``imu_r``, ``tacho_r``, ``gps_r``), for a
  positioning unit in each cab.

They exist only where the network has those tracks (the bundled sample network).
"""

from __future__ import annotations

from typing import Any

from dbtools.network import Network
from dbtools.topology import all_tracks

NEEDED = ("0420-D1", "0420-U5", "0420-X1", "0420-3", "0420-4", "0421-S1")


def network_sample_scenarios(network: Network) -> dict[str, dict[str, Any]]:
    """Scenario overrides of the network sample runs ({} without the sample's network)."""
    ids = set(all_tracks(network)["track_id"].astype(str))
    if not all(t in ids for t in NEEDED):
        return {}
    no_slip = {"slips": 0, "slides": 1}
    return {
        "sim-net-crossover": {
            "name": "sample: up train crosses to the down track on crossover X1",
            "seed": 111,
            "run": {"run_id": "SIM-NET-XO", "vehicle_id": "EMU-104", "start_time": "2026-01-15T11:10:00+09:00"},
            "network": {
                "from_track": "0420-U5",
                "to_track": "0420-D1",
                "via": ["0420-X1"],
                "points": [["0420-U5", 3200.0], ["0420-D1", 2600.0]],
            },
            "slip": no_slip,
        },
        "sim-net-station": {
            "name": "sample: arrive on station track 3 (roof: no GNSS), depart onto D",
            "seed": 112,
            "run": {"run_id": "SIM-NET-ST", "vehicle_id": "EMU-105", "start_time": "2026-01-15T11:40:00+09:00"},
            "network": {
                "from_track": "0420-D1",
                "to_track": "0420-D6",
                "via": ["0420-3"],
                "points": [["0420-D1", 1200.0], ["0420-3", 280.0], ["0420-D6", 3000.0]],
                "gnss_outages": [["0420-3", 150.0, 400.0]],
                "multipath": [["0420-D1", 3500.0, 4500.0, 2.5]],
            },
            "slip": no_slip,
        },
        "sim-net-junction": {
            "name": "sample: down train takes the branch line 0421 at the junction",
            "seed": 113,
            "run": {"run_id": "SIM-NET-JN", "vehicle_id": "EMU-106", "start_time": "2026-01-15T12:15:00+09:00"},
            "network": {
                "from_track": "0420-D1",
                "to_track": "0421-S1",
                "points": [["0420-D1", 1000.0], ["0421-S1", 1400.0]],
                "gnss_outages": [["0421-S1", 600.0, 900.0]],
            },
            "slip": no_slip,
        },
        "sim-net-turnback": {
            "name": "sample: up train turns back on station track 4 (cab change)",
            "seed": 114,
            "run": {"run_id": "SIM-NET-TB", "vehicle_id": "EMU-107", "start_time": "2026-01-15T12:50:00+09:00"},
            "network": {
                "tracks": ["0420-U5", "0420-U4", "0420-U3", "0420-4"],
                "points": [["0420-U5", 2200.0], ["0420-4", 250.0], ["0420-U5", 1800.0]],
            },
            "slip": no_slip,
            "cab_r": {"sensors": True},  # a unit per cab, each on its own sensors [S003 §2]
        },
    }
