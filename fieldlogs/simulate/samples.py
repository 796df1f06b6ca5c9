"""Bundled sample runs: a handful of short simulated runs over one line of an onboard DB.

``make_sample_runs(db_path, out_dir)`` writes (Parquet, zstd, 5–15 min each):

* ``sim-d-slips`` — down track in its normal direction (km increasing), station stops,
  2 slips + 2 slides (one on a gradient-plus-curve section when the line has one), radar;
* ``sim-u-tunnel`` — up track (km decreasing), a 600 m GPS outage (tunnel), slides and a slip;
* ``sim-d-reversal`` — down track, stop, change ends, run back reversed (cab R);
* ``sim-d-evening``, ``sim-u-evening`` — another vehicle on both tracks (for per-route statistics);
* ``sim-road-rail`` — road-rail vehicle: on rail at a km (PTO 1), works back and forth in a
  600 m section at 15 km/h, off rail; GPS + cab + tacho, no balises;
* over a network's station, crossovers and junction: ``sim-net-*`` (:mod:`.samples_net`).

Each run's ``run.json`` carries ``sim_truth`` (true wheel diameter, slip episodes, outages).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from dbtools.database import read_network
from fieldlogs.runs.typed import LogFormat
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.samples_net import network_sample_scenarios
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.enums import Track
from schemas.errors import InputError

#: Longest stretch of line a sample train run covers [m] (about 10 min at 95 km/h).
SAMPLE_RUN_M = 9000.0


def _span(gis: Any, line: str, track: str, margin: float = 200.0) -> tuple[float, float]:
    km = gis.loc[(gis["line_code"] == line) & (gis["track"] == track), "km_m"]
    return float(km.min()) + margin, float(km.max()) - margin


def sample_scenarios(network: Any, line_code: str | None = None) -> dict[str, dict[str, Any]]:
    """Scenario overrides of every sample run, fitted to the line's GIS range."""
    gis = network.gis
    line = line_code or sorted(set(gis["line_code"].astype(str)))[0]
    tracks = set(gis.loc[gis["line_code"] == line, "track"].astype(str))
    down = Track.DOWN.value if Track.DOWN in tracks else Track.SINGLE.value
    up = Track.UP.value if Track.UP in tracks else down
    lo, hi = _span(gis, line, down)
    length = min(hi - lo, SAMPLE_RUN_M)
    lo_u, hi_u = _span(gis, line, up)
    len_u = min(hi_u - lo_u, SAMPLE_RUN_M)
    mid_u = hi_u - 0.5 * len_u
    rr0 = lo + 0.4 * (hi - lo)
    base = {"route": {"line_code": line}}
    return {
        "sim-d-slips": {
            **base,
            "name": "sample: down track, slips and slides",
            "seed": 101,
            "run": {"run_id": "SIM-D-SLIPS", "vehicle_id": "EMU-101", "start_time": "2026-01-15T09:05:00+09:00"},
            "route": {"line_code": line, "track": down, "path_km_m": [lo, lo + length]},
            "slip": {"slips": 2, "slides": 2, "on_grade_curve": True},
            "sensors": {"radar": True},
        },
        "sim-u-tunnel": {
            "name": "sample: up track with a GPS outage (tunnel)",
            "seed": 102,
            "run": {"run_id": "SIM-U-TUNNEL", "vehicle_id": "EMU-102", "start_time": "2026-01-15T10:40:00+09:00"},
            "route": {"line_code": line, "track": up, "path_km_m": [hi_u, hi_u - len_u]},
            "slip": {"slips": 1, "slides": 2},
            "gps": {"outages_km_m": [[mid_u - 300.0, mid_u + 300.0]]},
        },
        "sim-d-reversal": {
            "name": "sample: stop, change ends, run back reversed",
            "seed": 103,
            "run": {"run_id": "SIM-D-REV", "vehicle_id": "EMU-101", "start_time": "2026-01-15T13:20:00+09:00"},
            "route": {
                "line_code": line,
                "track": down,
                "path_km_m": [lo, lo + 0.6 * length, lo + 0.3 * length],
            },
            "slip": {"slips": 1, "slides": 1},
        },
        "sim-d-evening": {
            "name": "sample: down track, another vehicle, one slide",
            "seed": 105,
            "run": {"run_id": "SIM-D-EVE", "vehicle_id": "EMU-103", "start_time": "2026-01-15T18:02:00+09:00"},
            "route": {"line_code": line, "track": down, "path_km_m": [lo, lo + length]},
            "slip": {"slips": 0, "slides": 1},
        },
        "sim-u-evening": {
            "name": "sample: up track, another vehicle, one slip",
            "seed": 106,
            "run": {"run_id": "SIM-U-EVE", "vehicle_id": "EMU-103", "start_time": "2026-01-15T18:40:00+09:00"},
            "route": {"line_code": line, "track": up, "path_km_m": [hi_u, hi_u - len_u]},
            "slip": {"slips": 1, "slides": 0},
        },
        "sim-road-rail": {
            "name": "sample: road-rail vehicle working inside a section",
            "seed": 104,
            "run": {
                "run_id": "SIM-RR",
                "vehicle_id": "RR-07",
                "vehicle_kind": "road_rail",
                "start_time": "2026-01-16T01:10:00+09:00",
            },
            "route": {"line_code": line, "track": down, "path_km_m": [rr0, rr0 + 450.0, rr0 + 150.0, rr0 + 600.0, rr0]},
            "running": {"line_speed_kmh": 15.0, "accel_kmh_s": 1.5, "brake_kmh_s": 2.0, "dwell_s": 30.0},
            "road_rail": {"off_rail_before_s": 60.0, "off_rail_after_s": 45.0},
            "sensors": {"imu": False, "tacho": True, "gps": True, "balise": False},
            "slip": {"slips": 0, "slides": 0},
        },
    }


def make_sample_runs(
    db_path: Path, out_dir: Path, *, line_code: str | None = None, fmt: LogFormat = "parquet", force: bool = False
) -> list[Path]:
    """Simulate the sample runs over ``db_path`` into ``out_dir/<run name>``; returns the folders."""
    network = read_network(Path(db_path))
    if network.gis.empty:
        raise InputError("the DB has no GIS grid to run on", path=db_path)
    out: list[Path] = []
    runs = {**sample_scenarios(network, line_code), **network_sample_scenarios(network)}
    for name, over in runs.items():
        scenario = scenario_from_dict(over, source=f"sample '{name}'")
        streams, meta = simulate_run(network, scenario)
        out.append(write_run(Path(out_dir) / name, meta, streams, fmt=fmt, force=force))
    return out


def main() -> None:
    """Regenerate the bundled sample logs: ``python -m fieldlogs.simulate.samples``."""
    import tempfile

    from dbtools.build import build_db
    from dbtools.sample_network import sample_network_source_dir

    target = Path(__file__).resolve().parent.parent / "sample_logs"
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "sample.sqlite"
        build_db(sample_network_source_dir(), db, db_version="sample-1")
        for path in make_sample_runs(db, target, force=True):
            print(path)


if __name__ == "__main__":
    main()
