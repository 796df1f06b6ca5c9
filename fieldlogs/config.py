"""The suite's configuration tree: every setting of every application, declared once.

One TOML file (``--config FILE.toml``) configures every command: ``run``, ``audit`` and
``gis verify`` read the pipeline's sections (``[odometry]``, ``[balise]``, ``[feature]``,
``[gps]``, ``[margin]``, ``cycle_s``), ``possession check`` reads ``[gps]`` and
``[possession]``, ``gis verify`` ``[gis_verify]``; each command ignores the sections of the
others but refuses unknown ones. ``trainpos config show`` prints the whole tree (or one
section) with every default, unit, range and meaning as commented TOML; fed back with
``--config`` it changes nothing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fieldlogs.pipeline.config import PipelineConfig, read_toml
from schemas.errors import UsageError
from schemas.settings import describe, render_toml


def default_tree() -> PipelineConfig:
    """The whole tree with its defaults."""
    return PipelineConfig()


def load_tree(path: Path | None) -> PipelineConfig:
    """The tree with the overrides of ``path`` (defaults without a file)."""
    return PipelineConfig.from_toml(path) if path is not None else default_tree()


def section_names(tree: Any) -> list[str]:
    return [k for k, v in describe(tree).items() if "value" not in v]


def show_toml(tree: Any, section: str | None = None) -> str:
    _known(tree, section)
    return render_toml(tree, section)


def show_dict(tree: Any, section: str | None = None) -> dict[str, Any]:
    _known(tree, section)
    return describe(tree, section)


def _known(tree: Any, section: str | None) -> None:
    names = section_names(tree)
    if section is not None and section not in names:
        raise UsageError(f"no config section '{section}' (known: {', '.join(names)})")


__all__ = ["default_tree", "load_tree", "read_toml", "section_names", "show_dict", "show_toml"]
