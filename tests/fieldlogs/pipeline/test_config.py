"""Pipeline parameters from TOML: overrides typed, unknown keys and bad values refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from fieldlogs.pipeline.config import PipelineConfig
from schemas.errors import InputError


def test_overrides_are_typed(tmp_path: Path) -> None:
    p = tmp_path / "c.toml"
    p.write_text("[odometry]\nbeta_kmh_s = 1\n[gps]\nwindows_s = [5, 15]\n", encoding="utf-8")
    cfg = PipelineConfig.from_toml(p)
    assert cfg.odometry.beta_kmh_s == 1.0 and isinstance(cfg.odometry.beta_kmh_s, float)
    assert cfg.gps.windows_s == (5, 15)
    assert cfg.feature == PipelineConfig().feature


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"odometry": {"beta": 1.0}}, "unknown key 'odometry.beta'"),
        ({"odometri": {}}, "unknown section or key 'odometri'"),
        ({"odometry": {"beta_kmh_s": "fast"}}, "'odometry.beta_kmh_s' must be a number"),
        ({"odometry": {"beta_kmh_s": float("inf")}}, "'odometry.beta_kmh_s' must be a number"),
        ({"odometry": {"hold_cycles": 2.5}}, "'odometry.hold_cycles' must be a whole number"),
        ({"gps": {"allow_initial": 1}}, "'gps.allow_initial' must be true or false"),
    ],
)
def test_bad_values_name_the_key(data: dict, message: str) -> None:
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        PipelineConfig.from_dict(data, source="c.toml")
