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


@pytest.mark.parametrize(
    ("data", "keys"),
    [
        ({"clock": {"tolerance_s": 1.0}}, ("clock.tolerance_s", "feature.clock_budget_s")),
        ({"clock": {"balise_tolerance_s": 0.3}}, ("clock.balise_tolerance_s", "balise.latency_budget_s")),
        ({"balise": {"latency_budget_s": 0.05}}, ("clock.balise_tolerance_s", "balise.latency_budget_s")),
    ],
)
def test_a_tolerance_above_its_budget_is_refused(data: dict[str, object], keys: tuple[str, str]) -> None:
    """An offset a check leaves uncorrected must be held by the fixes' budget (issue 15)."""
    from fieldlogs.config import SuiteConfig

    for load in (PipelineConfig.from_dict, SuiteConfig.from_dict):
        with pytest.raises(InputError) as exc:
            load(data, source="c.toml")
        assert all(k in exc.value.message for k in keys) and exc.value.path == "c.toml"


def test_a_tolerance_raised_with_its_budget_is_accepted_in_either_order() -> None:
    from fieldlogs.config import SuiteConfig

    for data in (
        {"clock": {"tolerance_s": 1.0}, "feature": {"clock_budget_s": 1.0}},
        {"feature": {"clock_budget_s": 1.0}, "clock": {"tolerance_s": 1.0}},
    ):
        assert PipelineConfig.from_dict(data).clock.tolerance_s == 1.0
        assert SuiteConfig.from_dict(data).feature.clock_budget_s == 1.0
