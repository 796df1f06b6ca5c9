"""Shared data of the audit tests: a synthetic onboard DB and four short simulated runs.

Built once per test session (``audit_data(tmp_path_factory)`` caches it) so that the
library and CLI test modules share it: an 8 km double-track line (``demo_line``), runs of
about 4 minutes over 3 km stretches that pass an initial pair and two correction balises,
each with one slip and one slide.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.geometry import Projector
from dbtools.sources import write_source_set
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

#: (run folder, track, path km, vehicle, seed)
RUNS = (
    ("d-west", "D", [1100.0, 4150.0], "EMU-01", 11),
    ("u-east", "U", [7900.0, 4850.0], "EMU-02", 12),
    ("d-east", "D", [4100.0, 7150.0], "EMU-01", 13),
    ("u-west", "U", [4900.0, 1850.0], "EMU-02", 14),
)


@dataclass(frozen=True)
class AuditData:
    db: Path
    sources: Path
    logs: Path
    """Folder holding one sub-folder per run."""

    @property
    def runs(self) -> list[Path]:
        return [self.logs / name for name, *_ in RUNS]

    def copy_logs(self, dst: Path) -> Path:
        """A private copy of the runs (safe to damage)."""
        shutil.copytree(self.logs, dst)
        return dst


_CACHE: dict[str, AuditData] = {}


def audit_data(factory: pytest.TempPathFactory) -> AuditData:
    if "data" not in _CACHE:
        root = factory.mktemp("audit-data")
        sources = write_source_set(build_network([demo_line(length_m=8000.0)], Projector(9)), root / "src")
        db = root / "net.sqlite"
        build_db(sources, db, db_version="2026.02-audit-test")
        net = read_network(db)
        for name, track, path, vehicle, seed in RUNS:
            scenario = scenario_from_dict(
                {
                    "run": {"run_id": f"RUN-{name}", "vehicle_id": vehicle},
                    "route": {"track": track, "path_km_m": path},
                    "slip": {"slips": 1, "slides": 1},
                }
            )
            sim = simulate_run(net, scenario, seed=seed)
            write_run(root / "logs" / name, sim.meta, sim.streams)
        _CACHE["data"] = AuditData(db, sources, root / "logs")
    return _CACHE["data"]
