"""A working folder holding folders named like the suite's packages does not break the pool.

``trainpos audit`` run from a folder with ``fieldlogs/simulate/`` in it (README's walk-through
in a scratch folder holding copies of the sample data) used to lose its workers: the fork
server, started as ``python -c``, had the working folder first on ``sys.path`` and imported
``fieldlogs.simulate`` from there as an empty namespace package, shadowing the editable
install. The coordinator here is a script outside the working folder (so, like the
``trainpos`` console script, it has no working folder on its own ``sys.path``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

DRIVER = """
import json, os, sys
from fieldlogs.replay.pool import replay
from workers import run_info

if __name__ == "__main__":
    tasks = [(r, (0.4,)) for r in sys.argv[1:]]
    out = [(o.error, o.value["pid"] if o.value else None) for o in replay(run_info, tasks, workers=2)]
    print(json.dumps({"coordinator": os.getpid(), "outcomes": out}))
"""


def test_package_named_folders_in_the_working_folder_do_not_shadow_the_suite(tmp_path: Path) -> None:
    here = tmp_path / "here"
    for name in ("fieldlogs/simulate/scenarios", "fieldlogs/replay", "dbtools/gis", "schemas"):
        (here / name).mkdir(parents=True)
    runs = []
    for k in range(10):
        run = here / "fieldlogs" / "sample_logs" / f"run-{k}"
        run.mkdir(parents=True)
        (run / "run.json").write_text(json.dumps({"run_id": f"R{k}"}), encoding="utf-8")
        runs.append(str(run))
    driver = tmp_path / "driver" / "drive.py"
    driver.parent.mkdir()
    driver.write_text(DRIVER, encoding="utf-8")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSAFEPATH")}
    env["PYTHONPATH"] = str(ROOT / "tests" / "fieldlogs" / "replay")  # `workers`, not the repository root
    res = subprocess.run(
        [sys.executable, str(driver), *runs], cwd=here, env=env, capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads(res.stdout)
    assert [e for e, _ in got["outcomes"]] == [None] * len(runs), res.stderr[-3000:]
    assert {pid for _, pid in got["outcomes"]} - {got["coordinator"]}, "the pool replayed no run"
