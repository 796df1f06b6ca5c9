"""Fixtures of the pipeline tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from dbtools.database import read_network
from fieldlogs.pipeline.aids.registry import RunContext
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.run import prepare_run
from fieldlogs.runs.handle import read_run

SAMPLE_LOGS = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs"


@pytest.fixture(scope="module")
def sample_run_context(sample_db: Path) -> RunContext:
    """The prepared context of the bundled run with slips, balises, GPS and radar."""
    ctx, _ = prepare_run(read_run(SAMPLE_LOGS / "sim-d-slips"), read_network(sample_db), PipelineConfig())
    return ctx
