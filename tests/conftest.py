"""Shared fixtures: tiny source sets and DBs on tmp paths, a CLI runner."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, settings
from typer.testing import CliRunner

DATA = Path(__file__).parent / "data"

# Property tests check results, never time: no per-example deadline and no "too slow" health
# check, so a loaded CI machine cannot fail a correct test (timing lives in bench/).
settings.register_profile("trainpos", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("trainpos")


@pytest.fixture
def runner() -> CliRunner:
    return CliRunner()


@pytest.fixture
def tiny_sources(tmp_path: Path) -> Path:
    """A copy of the tiny hand-made source set (safe to damage)."""
    dst = tmp_path / "src"
    shutil.copytree(DATA / "tiny_sources", dst)
    return dst


@pytest.fixture(scope="session")
def sample_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bundled sample network built once per session (read-only by convention)."""
    from dbtools.build import build_db
    from dbtools.sample_network import sample_source_dir

    db = tmp_path_factory.mktemp("sample-db") / "sample.sqlite"
    build_db(sample_source_dir(), db, db_version="sample-test")
    return db


@pytest.fixture(scope="session")
def sample_network_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample network with its station, crossovers and junction (``network_sources``), once."""
    from dbtools.build import build_db
    from dbtools.sample_network import sample_network_source_dir

    db = tmp_path_factory.mktemp("sample-network-db") / "sample.sqlite"
    build_db(sample_network_source_dir(), db, db_version="sample-1")
    return db


@pytest.fixture(scope="session")
def browser() -> Iterator[Any]:
    """One headless Chromium for the session's page tests (tests/pages.py); skipped where
    chromium is not installed (.ci/run installs it)."""
    from tests.cdp import Browser, chromium

    exe = chromium()
    if exe is None:
        pytest.skip("chromium is not installed (.ci/run installs it)")
    with Browser(exe, 1280, 800) as b:
        yield b
