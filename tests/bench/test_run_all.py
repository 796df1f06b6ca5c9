"""``bench/run_all.py`` writes RESULTS.md itself: dated, with the load average, and a partial
run (``--only``) redoes its rows in place and keeps the others with their own dates, so the
file never needs a hand edit."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

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


def _full(name: str, result: str, when: str = "2026-12-05 04:00 UTC") -> Any:
    return ra.Row(
        f"the {name}",
        f".venv/bin/python bench/bench_db.py --{name} 1",
        result,
        30.0,
        0.5,
        0.9,
        when,
        name,
        f"size of {name}",
        f"target of {name}",
    )


def _quick_then_full(out: Path) -> list[str]:
    """A quick table of two rows, then a full table of two rows of one script: the quick lines."""
    ra.write_results([_row("bench_a.py", "a quick"), _row("bench_db.py", "db quick")], out, ra.Started.now([]), [])
    quick: list[str] = ra.kept_rows(out)
    full = [_full("db", "db full: 1.2× (target ≤ 1.3×): met"), _full("db_network", "net full")]
    ra.write_results(full, out, ra.Started.now(["--full"]), [], table=ra.FULL)
    return quick


def test_a_full_run_writes_its_own_table_and_keeps_the_quick_one(tmp_path: Path) -> None:
    out = tmp_path / "RESULTS.md"
    quick = _quick_then_full(out)
    assert ra.kept_rows(out) == quick  # not one quick line touched by the full run (same script: bench_db.py)
    text = out.read_text(encoding="utf-8")
    assert text.index(ra.QUICK.title) < text.index(ra.FULL.title)
    assert "`bench/run_all.py --full`: started" in text.split(ra.FULL.title)[1]
    assert "`bench/run_all.py --full`" not in text.split(ra.FULL.title)[0]  # the quick table keeps its own date
    full = ra.kept_rows(out, ra.FULL)
    assert [ra._key_of(line, ra.FULL) for line in full] == ["db", "db_network"]
    assert full[0].startswith(
        "| db | size of db | target of db | db full: 1.2× (target ≤ 1.3×): met | `.venv/bin/python bench/bench_db.py"
    )
    assert "| net full | 30 s | 0.5 → 0.9 | 2026-12-05 04:00 UTC |" in full[1]
    assert "| db_network | size of db_network | target of db_network | — |" in full[1]  # no verdict printed
    timed = ra.Row("c", "bench/bench_x.py", "r", 31.6, 0.5, 0.9, "now", cpu_s=28.2).markdown()
    assert "| r | 32 s (28 s CPU) | 0.5 → 0.9 | now |" in timed


def test_a_partial_full_run_replaces_only_its_full_row(tmp_path: Path) -> None:
    out = tmp_path / "RESULTS.md"
    quick = _quick_then_full(out)
    ra.write_results(
        [_full("db_network", "net again")],
        out,
        ra.Started.now(["--full", "--only", "db_network"]),
        ra.kept_rows(out, ra.FULL),
        table=ra.FULL,
    )
    full = ra.kept_rows(out, ra.FULL)
    assert "db full" in full[0] and "net again" in full[1] and len(full) == 2
    assert ra.kept_rows(out) == quick
    # and a quick run (whole or partial) leaves the full table as it was
    ra.write_results([_row("bench_db.py", "db quick again")], out, ra.Started.now([]), [])
    assert ra.kept_rows(out, ra.FULL) == full
    assert [ra._script_of(line) for line in ra.kept_rows(out)] == ["bench_db.py"]


def test_a_file_of_the_layout_before_the_sections_keeps_its_rows_as_the_quick_table(tmp_path: Path) -> None:
    out = tmp_path / "RESULTS.md"
    old = [_row("bench_a.py", "a old", "2026-12-01 10:00 UTC")]
    old_text = "# Benchmark results\n\n* last written by `bench/run_all.py`: long ago\n\n"
    old_text += f"{ra.TABLE_HEAD}\n{ra.QUICK.rule}\n{old[0].markdown()}\n"
    out.write_text(old_text, encoding="utf-8")
    ra.write_results([_full("db", "db full")], out, ra.Started.now(["--full"]), [], table=ra.FULL)
    assert ra.kept_rows(out) == [old[0].markdown()]
    assert "* last written by `bench/run_all.py`: long ago" in out.read_text(encoding="utf-8").split(ra.FULL.title)[0]


def test_verdict_lines_are_the_targets_met_or_not() -> None:
    row = _full("db", "setup 3 s\nA 1.25× (target ≤ 1.3×): met\nB 1.6× (target ≤ 1.5×): not met  [load 0.9]\nC 2×")
    assert row.verdict == "A 1.25× (target ≤ 1.3×): met\nB 1.6× (target ≤ 1.5×): not met  [load 0.9]"
    assert _full("x", "speed 3× (target ≥ 2×; quiet machine)").verdict == ""


def test_every_full_row_has_a_size_a_target_and_a_unique_name() -> None:
    full = [b for b in ra.BENCHES if b.full is not None]
    names = [b.name for b in ra.BENCHES]
    assert len(names) == len(set(names))
    assert all(b.full.size and b.full.target for b in full)
    issue_rows = {"db", "db_network", "audit", "audit_small", "scaling", "run", "engine", "track_match", "osm"}
    assert issue_rows <= {b.name for b in full}
    scripts = [b.path.name for b in ra.BENCHES if b.quick is not None]
    assert len(scripts) == len(set(scripts)), "two quick rows of one script would replace each other"


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--full", "--only", "pipeline"], "no full size for pipeline"),
        (["--only", "db_network"], "no quick size for db_network"),
        (["--full", "--only", "nosuch"], "no benchmark named nosuch"),
    ],
)
def test_only_names_a_row_of_the_table_it_writes(
    argv: list[str], says: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr("sys.argv", ["run_all.py", *argv, "--out", str(tmp_path / "R.md")])
    with pytest.raises(SystemExit):
        ra.main()
    assert says in capsys.readouterr().err
    assert not (tmp_path / "R.md").exists()
