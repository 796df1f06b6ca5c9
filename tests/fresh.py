"""Run a snippet in a fresh interpreter: what a new process imports, compiles or leaves
behind cannot be seen from inside the test process, which has long imported everything."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def fresh_python(code: str, *args: str, timeout: float = 300) -> str:
    """``python -c code args…`` from the checkout's root with this test run's interpreter; its
    standard output. A snippet that fails fails the test with the snippet's stderr."""
    proc = subprocess.run(
        [sys.executable, "-c", code, *args], cwd=ROOT, capture_output=True, text=True, check=False, timeout=timeout
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout
