"""The performance page (docs/explanation/performance.md, once README's section) points
at the benchmark results `make bench` writes, and
names every benchmark script."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _section() -> str:
    text = (ROOT / "docs" / "explanation" / "performance.md").read_text(encoding="utf-8")
    assert text.startswith("# Performance"), "docs/explanation/performance.md is not the performance page"
    return text


def test_readme_links_the_results_that_make_bench_writes() -> None:
    assert "`bench/RESULTS.md`" in _section()  # named, not linked: the docs site holds docs/ only
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    bench_target = re.search(r"^bench:.*?\n((?:\t.*\n)+)", makefile, re.M)
    assert bench_target is not None and "bench/run_all.py" in bench_target.group(1)
    run_all = (ROOT / "bench" / "run_all.py").read_text(encoding="utf-8")
    assert 'default=BENCH / "RESULTS.md"' in run_all, "bench/run_all.py no longer writes bench/RESULTS.md"


def test_every_benchmark_script_is_in_the_table() -> None:
    section = _section()
    scripts = [*sorted(p.name for p in (ROOT / "bench").glob("bench_*.py")), "accuracy.py"]
    missing = [s for s in scripts if f"bench/{s}" not in section]
    assert not missing, f"README's performance table lacks {missing}"


def test_make_bench_runs_every_benchmark_script() -> None:
    """`make bench` (bench/run_all.py) has a row for every bench/bench_*.py."""
    spec = importlib.util.spec_from_file_location("run_all", ROOT / "bench" / "run_all.py")
    assert spec is not None and spec.loader is not None
    run_all = importlib.util.module_from_spec(spec)
    sys.modules["run_all"] = run_all  # dataclasses resolve the module's annotations through it
    try:
        spec.loader.exec_module(run_all)
        listed = {b.path.name for b in run_all.BENCHES}
    finally:
        del sys.modules["run_all"]
    scripts = {p.name for p in (ROOT / "bench").glob("bench_*.py")}
    assert not scripts - listed, f"bench/run_all.py does not run {sorted(scripts - listed)}"
    assert not listed - scripts, f"bench/run_all.py lists missing scripts {sorted(listed - scripts)}"
