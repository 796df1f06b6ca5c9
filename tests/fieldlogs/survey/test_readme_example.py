"""The user guide's survey maintenance loop (docs/guide/survey.md) — survey → --propose →
db build → db diff → db impact → db release — runs as written, every command succeeding
(``set -e``; the survey's exit 1 is the page's own ``|| [ $? -eq 1 ]``), in a scratch folder that sees the repository's
``dbtools`` and ``fieldlogs`` under the same relative paths."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def _block() -> str:
    text = (ROOT / "docs" / "guide" / "survey.md").read_text(encoding="utf-8")
    m = re.search(r"<!-- survey-example:begin -->\n```bash\n(.*?)```\n<!-- survey-example:end -->", text, re.S)
    assert m is not None, "docs/guide/survey.md lost the survey example"
    return m.group(1)


def test_the_readme_maintenance_loop_runs(tmp_path: Path) -> None:
    for name in ("dbtools", "fieldlogs"):
        (tmp_path / name).symlink_to(ROOT / name)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}", "COLUMNS": "200"}
    env["OMP_NUM_THREADS"] = "1"
    res = subprocess.run(
        ["bash", "-e", "-c", _block()], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600, check=False
    )
    assert res.returncode == 0, res.stderr[-3000:]  # every command succeeded
    assert "balise 0420-D-C002 (C, 0420 03 D) moved -3.0 m" in res.stdout
    changes = json.loads((tmp_path / "src-next" / "survey_changes.json").read_text())["changes"]
    moves = [c for c in changes if c["action"] == "move"]
    assert [(c["key"], c["applied"]) for c in moves] == [("0420-D-C002", True)]
    assert abs(float(moves[0]["new"]) - 23469.0) <= 0.5  # where the runs were simulated
    assert (tmp_path / "survey.html").stat().st_size > 10_000
    impact = json.loads((tmp_path / "impact.json").read_text())
    assert impact["totals"]["runs"] == 4 and impact["totals"]["runs_changed"] >= 2
    moved = [
        c
        for r in impact["runs"]
        for c in r["changed_corrections"]
        if c["row"] == "0420-D-C002" and c["old_m"] is not None and c["new_m"] is not None
    ]
    assert moved and all(abs(abs(c["old_m"] - c["new_m"]) - 3.0) < 0.5 for c in moved)
    assert (tmp_path / "releases" / "registry.sqlite").is_file()
    stored = json.loads((tmp_path / "releases" / "2026.12.impact.json").read_text())
    assert stored["old"]["db_version"] == "2026.10" and stored["new"]["db_version"] == "2026.12"
    assert not (ROOT / "dbtools" / "sample_network" / "sources" / "survey_changes.json").exists()
