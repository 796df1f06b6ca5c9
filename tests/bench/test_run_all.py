"""``bench/run_all.py`` writes RESULTS.md itself: dated, with the load average, and a partial
run (``--only``) redoes its rows in place and keeps the others with their own dates, so the
file never needs a hand edit."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from tests.bench.scripts import load_script

ra = load_script("run_all")


def _row(script: str, result: str, when: str = "2026-12-05 03:00 UTC") -> Any:
    return ra.Row(f"the {script}", f".venv/bin/python bench/{script} --x 1", result, 12.0, 1.5, 2.5, when)


def test_results_are_dated_with_the_load_average(tmp_path: Path) -> None:
    out = tmp_path / "RESULTS.md"
    ra.write_results([_row("bench_a.py", "fast: 3.0×\nslow | 1.0×")], out, ra.Started.now(["--only", "a"]), [])
    text = out.read_text(encoding="utf-8")
    stamp = r"\d{4}-\d\d-\d\d \d\d:\d\d UTC, load average [\d.]+ / [\d.]+ / [\d.]+"
    assert re.search(rf"`bench/run_all.py --only a`: started {stamp}; finished {stamp}", text)
    ra.write_results([], out, ra.Started.now([]), [], done=False)
    assert re.search(rf"started {stamp}; not finished \(table so far\) {stamp}", out.read_text(encoding="utf-8"))
    assert ra.TABLE_HEAD in text
    assert (
        "| the bench_a.py | `.venv/bin/python bench/bench_a.py --x 1` | fast: 3.0×<br>slow \\| 1.0× | 12 s | "
        "1.5 → 2.5 | 2026-12-05 03:00 UTC |"
    ) in text.splitlines()


def test_a_partial_run_replaces_its_rows_and_keeps_the_others(tmp_path: Path) -> None:
    out = tmp_path / "RESULTS.md"
    first = [_row("bench_a.py", "a old", "2026-12-01 10:00 UTC"), _row("bench_b.py", "b old", "2026-12-01 10:05 UTC")]
    ra.write_results(first, out, ra.Started.now([]), [])
    kept = ra.kept_rows(out)
    assert len(kept) == 2
    ra.write_results([_row("bench_b.py", "b new"), _row("bench_c.py", "c new")], out, ra.Started.now([]), kept)
    body = ra.kept_rows(out)
    assert [ra._script_of(line) for line in body] == ["bench_a.py", "bench_b.py", "bench_c.py"]
    assert "a old" in body[0] and "2026-12-01 10:00 UTC" in body[0]
    assert "b new" in body[1] and "b old" not in out.read_text(encoding="utf-8")


def test_rows_of_the_layout_before_the_when_column_are_kept_with_the_files_date(tmp_path: Path) -> None:
    out = tmp_path / "RESULTS.md"
    out.write_text(
        "# Benchmark results\n\nWritten by `bench/run_all.py` on 2026-12-01 20:06 UTC, 2 cores.\n\n"
        f"{ra.OLD_TABLE_HEAD}\n| --- | --- | --- | --- | --- |\n"
        "| start-up | `.venv/bin/python bench/bench_startup.py --repeat 3` | 1.80 s | 15 s | 3.6 → 3.3 |\n",
        encoding="utf-8",
    )
    assert ra.kept_rows(out) == [
        "| start-up | `.venv/bin/python bench/bench_startup.py --repeat 3` | 1.80 s | 15 s | 3.6 → 3.3 | "
        "2026-12-01 20:06 UTC (or later) |"
    ]
    assert ra.kept_rows(tmp_path / "missing.md") == []
