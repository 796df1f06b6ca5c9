"""Pipeline parameters from TOML: overrides typed, unknown keys and bad values refused."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fieldlogs.pipeline.config import OdometryConfig, PipelineConfig
from schemas.errors import InputError


def test_overrides_are_typed(tmp_path: Path) -> None:
    p = tmp_path / "c.toml"
    p.write_text(
        "[odometry]\nbeta_kmh_s = 1\n[gps]\nwindows_s = [5, 15]\nrms_threshold_m = [2.5, 2]\n", encoding="utf-8"
    )
    cfg = PipelineConfig.from_toml(p)
    assert cfg.odometry.beta_kmh_s == 1.0 and isinstance(cfg.odometry.beta_kmh_s, float)
    assert cfg.gps.windows_s == (5, 15) and cfg.gps.rms_threshold_m == (2.5, 2.0)
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
        # ranges (issue 14): a negative threshold or a zero window can never exist
        ({"odometry": {"ta_kmh_s": -1}}, "'odometry.ta_kmh_s' = -1.0 km/h/s is out of range (allowed: > 0)"),
        ({"balise": {"id_window_m": 0}}, "'balise.id_window_m' = 0.0 m is out of range (allowed: > 0)"),
        ({"gps": {"decide_error": 1.0}}, "'gps.decide_error' = 1.0 is out of range (allowed: > 0, < 1)"),
        ({"gps": {"windows_s": [5, 0, 30]}}, "'gps.windows_s' = (5, 0, 30) s is out of range (allowed: > 0)"),
        ({"gps": {"windows_s": [5, 15]}}, "need one threshold per window (2 windows, 3 thresholds)"),
        ({"cycle_s": 0.0}, "'cycle_s' = 0.0 s is out of range (allowed: > 0)"),
    ],
)
def test_bad_values_name_the_key(data: dict, message: str) -> None:
    with pytest.raises(InputError, match=re.escape(message)) as exc:
        PipelineConfig.from_dict(data, source="c.toml")
    assert exc.value.path is not None and str(exc.value.path) == "c.toml"


def test_ranges_hold_in_code_too() -> None:
    with pytest.raises(InputError, match=re.escape("'odometry.max_correction_s' = 0.0 s is out of range")):
        OdometryConfig(max_correction_s=0.0)
