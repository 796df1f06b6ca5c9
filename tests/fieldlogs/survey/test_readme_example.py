"""README's survey maintenance loop runs as written (in a scratch folder that sees the
repository's ``dbtools`` and ``fieldlogs`` under the same relative paths)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def _block() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    m = re.search(r"<!-- survey-example:begin -->\n```sh\n(.*?)```\n<!-- survey-example:end -->", text, re.S)
    assert m is not None, "README lost the survey example"
    return m.group(1)


def test_the_readme_maintenance_loop_runs(tmp_path: Path) -> None:
    for name in ("dbtools", "fieldlogs"):
        (tmp_path / name).symlink_to(ROOT / name)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}", "COLUMNS": "200"}
    env["OMP_NUM_THREADS"] = "1"
    res = subprocess.run(
        ["bash", "-c", _block()], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600, check=False
    )
    assert res.returncode == 0, res.stderr[-3000:]  # the last command (release) succeeded
    assert "balise 0420-D-C002 (C, 0420 03 D) moved -3.0 m" in res.stdout
    changes = json.loads((tmp_path / "src-next" / "survey_changes.json").read_text())["changes"]
    moves = [c for c in changes if c["action"] == "move"]
    assert [(c["key"], c["applied"]) for c in moves] == [("0420-D-C002", True)]
    assert abs(float(moves[0]["new"]) - 23469.0) <= 0.5  # where the runs were simulated
    assert (tmp_path / "survey.html").stat().st_size > 10_000
    assert (tmp_path / "releases" / "registry.sqlite").is_file()
    assert not (ROOT / "dbtools" / "sample_network" / "sources" / "survey_changes.json").exists()
