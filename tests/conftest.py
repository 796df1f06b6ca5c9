"""Shared fixtures: tiny source sets and DBs on tmp paths, a CLI runner."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

DATA = Path(__file__).parent / "data"


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


@pytest.fixture
def tiny_sources(tmp_path: Path) -> Path:
    """A copy of the tiny hand-made source set (safe to damage)."""
    dst = tmp_path / "src"
    shutil.copytree(DATA / "tiny_sources", dst)
    return dst
