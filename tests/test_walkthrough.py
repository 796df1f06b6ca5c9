"""README's and the docs pages' examples run top to bottom as written (the docs contract).

The convention (README states it in a comment under its title):

* The walk-through is README.md followed by the docs pages of :data:`WALK_PAGES`, in that
  order (the how-to guides continue README's quick start: each uses files the ones before it
  wrote); each tutorial of :data:`TUTORIALS` runs alone, top to bottom, in its own scratch
  folder. ``docs/howto/`` pages have tests of their own.
* Every ```` ```sh ```` block of those pages is run, in that order, in one scratch working
  folder: a temporary folder holding copies of the repository's data paths the commands name
  (anything under ``dbtools/``, ``fieldlogs/`` or ``tests/data/`` that exists in the checkout),
  with the test's own venv first on ``PATH`` (so ``trainpos`` is the checkout's), and
  ``OMP_NUM_THREADS=1``. Everything else a command reads was written by an earlier command.
* Each command runs in its own ``bash -c`` (continuation lines joined; a compound command such
  as a ``for`` loop is one command): no shell state carries over, only files.
* A command must exit 0, unless its line says otherwise with a trailing comment
  ``# exit N`` (the documented exit code of a command that fails on purpose, e.g. a
  ``survey`` that flags a balise exits 1).
* A block right after an HTML comment ``<!-- walkthrough: skip (reason) -->`` is not run (the
  set-up commands ``make demo`` / ``make test`` themselves); a block right after
  ``<!-- walkthrough: fresh (reason) -->`` runs alone in a new scratch folder (a self-contained
  example that builds its own DBs), and the walk-through goes on in its own folder after it.
  Other comment lines may stand between marker and block.
* ```` ```toml ````, ```` ```yaml ````, ```` ```text ```` and ```` ```console ```` blocks are never run.

The first command that does not exit as its page says fails the test with the page and line,
the command, its exit code and the tail of its output. ``python tests/test_walkthrough.py``
runs the same walk-through in a kept folder and reports every failing command, not just the
first (for fixing the pages; `python tests/test_walkthrough.py PAGE` runs one page alone).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: The pages that continue README's walk-through, in its order (each a former README section).
WALK_PAGES = (
    "README.md",
    "docs/reference/behaviour.md",
    "docs/guide/onboard-db.md",
    "docs/guide/field-logs.md",
    "docs/guide/radar.md",
    "docs/guide/pipeline.md",
    "docs/guide/gnss.md",
    "docs/guide/audits.md",
    "docs/guide/survey.md",
    "docs/guide/possessions.md",
    "docs/explanation/performance.md",
    "docs/development.md",
)
#: The tutorials: each runs alone in its own scratch folder.
TUTORIALS = (
    "docs/tutorials/first-network.md",
    "docs/tutorials/import-network.md",
    "docs/tutorials/fleet-audit.md",
    "docs/tutorials/ci-validation.md",
)
#: README paths under these prefixes are the repository's data: copied into the scratch folder.
DATA_PREFIXES = ("dbtools/", "fieldlogs/", "tests/data/")
RUN_LANG = "sh"
MARKER = re.compile(r"^<!--\s*walkthrough:\s*(skip|fresh)\b\s*(.*?)\s*-->$")
EXPECTED_EXIT = re.compile(r"#\s*exit\s+(\d+)\b")
TIMEOUT_S = 1200


@dataclass
class Command:
    line: int  # page line of the command's first line (1-based)
    text: str  # continuation lines joined
    expected_exit: int
    page: str = "README.md"


@dataclass
class Block:
    line: int  # page line of the opening fence
    lang: str
    marker: str | None  # "skip", "fresh" or None
    reason: str
    body: list[tuple[int, str]] = field(default_factory=list)
    page: str = "README.md"

    @property
    def runs(self) -> bool:
        return self.lang == RUN_LANG and self.marker != "skip"


def blocks(text: str, page: str = "README.md") -> list[Block]:
    """A page's fenced blocks with their walk-through markers."""
    out: list[Block] = []
    lines = text.splitlines()
    current: Block | None = None
    for no, line in enumerate(lines, start=1):
        if current is not None:
            if line.startswith("```"):
                out.append(current)
                current = None
            else:
                current.body.append((no, line))
        elif line.startswith("```"):
            marker, reason = _marker_before(lines, no - 1)
            current = Block(no, line[3:].strip(), marker, reason, page=page)
    assert current is None, f"{page} line {current.line}: unclosed ``` block"
    return out


def _marker_before(lines: list[str], index: int) -> tuple[str | None, str]:
    """The walk-through marker among the HTML comment lines right above line ``index`` (0-based)."""
    k = index - 1
    while k >= 0 and lines[k].startswith("<!--"):
        m = MARKER.match(lines[k].strip())
        if m:
            return m.group(1), m.group(2).strip("() ")
        k -= 1
    return None, ""


def _complete(text: str) -> bool:
    return subprocess.run(["bash", "-n", "-c", text], capture_output=True, check=False).returncode == 0


def commands(block: Block) -> list[Command]:
    """The block's commands: continuation lines joined, a compound command kept whole."""
    out: list[Command] = []
    pending: list[str] = []
    start = 0
    for no, raw in block.body:
        if not pending and (not raw.strip() or raw.lstrip().startswith("#")):
            continue
        if not pending:
            start = no
        pending.append(raw)
        if raw.endswith("\\") or not _complete("\n".join(pending)):
            continue
        text = "\n".join(pending)
        m = EXPECTED_EXIT.search(text)
        out.append(Command(start, text, int(m.group(1)) if m else 0, block.page))
        pending = []
    assert not pending, f"{block.page} line {start}: incomplete shell command {pending!r}"
    return out


def data_paths(cmds: list[Command]) -> list[str]:
    """The repository data paths the commands name (outermost first)."""
    found: set[str] = set()
    for cmd in cmds:
        try:
            tokens = shlex.split(cmd.text, comments=True)
        except ValueError:
            tokens = cmd.text.split()
        for token in tokens:
            path = token.rstrip("/")
            if path.startswith(DATA_PREFIXES) and (ROOT / path).exists():
                found.add(path)
    keep: list[str] = []
    for path in sorted(found, key=lambda p: (p.count("/"), p)):
        if not any(path == k or path.startswith(k + "/") for k in keep):
            keep.append(path)
    return keep


def scratch(folder: Path, cmds: list[Command]) -> Path:
    """A new working folder with copies of the data paths ``cmds`` name."""
    folder.mkdir(parents=True)
    for rel in data_paths(cmds):
        src, dst = ROOT / rel, folder / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(src, dst)
    return folder


def page_text(page: str) -> str:
    return (ROOT / page).read_text(encoding="utf-8")


def walkthrough(text: str | None = None, page: str = "README.md") -> list[tuple[int, Block, list[Command]]]:
    """The runnable blocks in the walk-through's order, each with its scratch folder's number:
    0 for the walk-through's one folder, a new number for every ``fresh`` block and every
    tutorial (it runs alone). ``text``: one page only (``page`` names it)."""
    pages = [(page, text)] if text is not None else [(p, page_text(p)) for p in (*WALK_PAGES, *TUTORIALS)]
    out: list[tuple[int, Block, list[Command]]] = []
    fresh = 0
    for name, body in pages:
        tutorial = name in TUTORIALS
        if tutorial:
            fresh += 1
        own = fresh
        for block in blocks(body, name):
            if not block.runs:
                continue
            if block.marker == "fresh":
                fresh += 1
                out.append((fresh, block, commands(block)))
            else:
                out.append((own if tutorial else 0, block, commands(block)))
    return out


def _env() -> dict[str, str]:
    bindir = Path(sys.executable).parent
    assert (bindir / "trainpos").exists(), f"no trainpos next to {sys.executable}: run `make .venv/.installed`"
    env = {k: v for k, v in os.environ.items() if k != "TRAINPOS_DEBUG"}
    env.update(PATH=f"{bindir}{os.pathsep}{env.get('PATH', '')}", OMP_NUM_THREADS="1", COLUMNS="200")
    return env


def _tail(text: str, n: int = 40) -> str:
    return "\n".join(text.rstrip().splitlines()[-n:])


def run_all(base: Path, timings: list[tuple[float, Command]] | None = None, only: str | None = None) -> Iterator[str]:
    """Run the walk-through under ``base``; yield one report per command that does not exit as
    its page says (``timings``: gets each command's wall time; ``only``: one page alone)."""
    env = _env()
    steps = walkthrough(page_text(only), only) if only else walkthrough()
    folders: dict[int, Path] = {}
    for k, block, cmds in steps:
        if k not in folders:
            folders[k] = scratch(base / f"walk-{k}", [c for j, _, cs in steps if j == k for c in cs])
        folder = folders[k]
        for cmd in cmds:
            t0 = time.perf_counter()
            res = subprocess.run(
                ["bash", "-c", cmd.text],
                cwd=folder,
                env=env,
                capture_output=True,
                text=True,
                timeout=TIMEOUT_S,
                check=False,
            )
            if timings is not None:
                timings.append((time.perf_counter() - t0, cmd))
            if res.returncode != cmd.expected_exit:
                yield (
                    f"{cmd.page} line {cmd.line} (block at line {block.line}, run in {folder}):\n"
                    f"$ {cmd.text}\nexit {res.returncode}, the page says {cmd.expected_exit}\n"
                    f"--- stdout (tail)\n{_tail(res.stdout)}\n--- stderr (tail)\n{_tail(res.stderr)}"
                )


# --- fast checks of the convention ------------------------------------------------------


def test_readme_states_the_convention() -> None:
    text = README.read_text(encoding="utf-8")
    assert "tests/test_walkthrough.py" in text.split("## ")[0], "README's top must state the walk-through convention"


def test_the_first_commands_are_make_demo_and_make_test() -> None:
    """The README contract: two commands from README's top do all the set-up."""
    first = next(b for b in blocks(README.read_text(encoding="utf-8")) if b.lang == RUN_LANG)
    lines = [line.split("#")[0].strip() for _, line in first.body if line.strip()]
    assert lines == ["make demo", "make test"], lines
    assert first.marker == "skip"


def test_every_page_with_examples_is_walked() -> None:
    """Every docs page with ```sh blocks is in the walk-through or a tutorial (docs/howto/: own tests)."""
    walked = {*WALK_PAGES, *TUTORIALS}
    for path in sorted((ROOT / "docs").rglob("*.md")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith("docs/howto/") or rel in walked:
            continue
        assert not [b for b in blocks(page_text(rel), rel) if b.lang == RUN_LANG], f"{rel}: sh blocks nobody runs"
    assert all((ROOT / p).is_file() for p in walked)


def test_every_shell_block_runs_or_says_why_not() -> None:
    for block in [b for p in (*WALK_PAGES, *TUTORIALS) for b in blocks(page_text(p), p)]:
        if block.lang == RUN_LANG and block.marker == "skip":
            assert block.reason, f"{block.page} line {block.line}: a skipped block must give its reason"
            assert all(line.split("#")[0].strip().startswith("make ") for _, line in block.body if line.strip()), (
                f"{block.page} line {block.line}: only the make set-up commands are exempt from the walk-through"
            )
    cmds = [c for _, _, cs in walkthrough() for c in cs]
    assert len(cmds) >= 60, len(cmds)
    assert any(c.expected_exit == 1 for c in cmds), "README shows commands failing on purpose (# exit 1)"


def test_commands_are_split_as_bash_reads_them() -> None:
    block = Block(1, "sh", None, "")
    block.body = list(
        enumerate(
            [
                "# a comment",
                "trainpos a --x 1 \\",
                "    --y 2",
                "for s in 1 2; do",
                "  trainpos b $s",
                "done",
                "",
                "trainpos c   # exit 1: on purpose",
            ],
            start=10,
        )
    )
    got = [(c.line, c.text.split()[0], c.expected_exit) for c in commands(block)]
    assert got == [(11, "trainpos", 0), (13, "for", 0), (17, "trainpos", 1)]


def test_data_paths_are_copied_outermost_first() -> None:
    cmds = [
        Command(1, "trainpos run fieldlogs/sample_logs/sim-d-slips --db net.sqlite --out out/x", 0),
        Command(2, "trainpos audit fieldlogs/sample_logs/ --db net.sqlite --out a.sqlite", 0),
        Command(3, "trainpos db build dbtools/sample_network/sources --out n.sqlite", 0),
        Command(4, "trainpos db build dbtools/no-such-folder --out n.sqlite", 0),
    ]
    assert data_paths(cmds) == ["fieldlogs/sample_logs", "dbtools/sample_network/sources"]


# --- the walk-through itself ------------------------------------------------------------


@pytest.mark.slow
def test_readme_walkthrough_runs_as_written(tmp_path: Path) -> None:
    failure = next(run_all(tmp_path), None)
    assert failure is None, failure
    assert not (ROOT / "dbtools" / "sample_network" / "sources" / "survey_changes.json").exists()


if __name__ == "__main__":  # every failure at once, in a kept folder (for fixing the pages)
    # `python tests/test_walkthrough.py [PAGE]`: the whole walk-through, or one page alone
    base = Path(tempfile.mkdtemp(prefix="walkthrough-"))
    timings: list[tuple[float, Command]] = []
    failures = list(run_all(base, timings, sys.argv[1] if len(sys.argv) > 1 else None))
    slowest = sorted(timings, key=lambda x: -x[0])[:15]
    sys.stdout.write("\n\n".join(failures) + f"\n{len(failures)} failing command(s); folder {base}\n")
    sys.stdout.write(f"{len(timings)} commands, {sum(t for t, _ in timings):.0f} s; slowest:\n")
    sys.stdout.write("".join(f"{t:7.1f} s  {c.page}:{c.line}: {c.text.splitlines()[0][:100]}\n" for t, c in slowest))
    sys.exit(1 if failures else 0)
