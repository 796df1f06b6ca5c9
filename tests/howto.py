"""The ``trainpos`` commands of a how-to page's ``sh`` blocks, as each page's own test runs
them (``docs/howto/``: those pages are not in the walk-through; their tests check the
numbers the page states)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def page_commands(page: Path) -> list[list[str]]:
    """Every ``trainpos …`` line of the page's ``sh`` blocks, in order, as argv without the
    program name; paths under ``tests/data/`` made absolute (the commands run in a scratch
    folder)."""
    out = []
    for block in re.findall(r"```sh\n(.*?)```", page.read_text(encoding="utf-8"), flags=re.S):
        for line in block.splitlines():
            if line.strip().startswith("trainpos "):
                argv = shlex.split(line)[1:]
                out.append([str(ROOT / a) if a.startswith("tests/data/") else a for a in argv])
    return out
