"""Run folders to replay: every folder holding a ``run.json`` at or below some roots."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from schemas.errors import InputError


def discover_runs(roots: Iterable[Path]) -> list[Path]:
    """Every folder holding a ``run.json`` below the given roots (a root may be a run),
    absolute and sorted; hidden folders (an atomic write in progress: ``.name.xxxx``) are
    skipped. InputError for a root that is not a folder."""
    found: set[Path] = set()
    for root in roots:
        root = Path(root)
        if not root.is_dir():
            raise InputError("no such folder", path=root)
        if (root / "run.json").is_file():
            found.add(root.resolve())
            continue
        for p in root.rglob("run.json"):
            rel = p.parent.relative_to(root).parts
            if not any(part.startswith(".") for part in rel):
                found.add(p.parent.resolve())
    return sorted(found)
