"""The odometry's stages are pure (odometry package docstring): the same inputs give equal
frozen results, in any order, without touching their inputs; and the pipeline's events
carry only the public episode fields, never the algorithm's internals.

Runs are the hand-built scenarios of ``test_odometry`` (exact 100 Hz kinematics, 3 cm
pulses) with a random slip or slide, cab, grade, IMU gaps and radar.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import shutil
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools.database import read_network
from fieldlogs.pipeline.aid import SpeedOnCycles
from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.odometry.assembly import assemble
from fieldlogs.pipeline.odometry.correct import correct_odometry
from fieldlogs.pipeline.odometry.detection import detect
from fieldlogs.pipeline.odometry.diagnostics import EpisodeDiagnostics, OdometryDiagnostics
from fieldlogs.pipeline.odometry.episodes import find_episodes
from fieldlogs.pipeline.odometry.ground import align_ground, metres_per_pulse
from fieldlogs.pipeline.odometry.ground_products import ground_products
from fieldlogs.pipeline.odometry.streams import align_streams
from fieldlogs.pipeline.run import PipelineResult, run_pipeline
from fieldlogs.pipeline.summary import DETAIL_DIGITS
from fieldlogs.pipeline.types import FailsafeWatch, SlipEpisode
from fieldlogs.runs.handle import read_run
from schemas.jsonable import jsonable
from tests.fieldlogs.pipeline.test_odometry import Scenario, const, scenario, slip_pulse

CFG = OdometryConfig()
SAMPLE_LOGS = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs"
#: Keys the slip/slide events carried before the episode got typed fields: algorithm state.
LEGACY_INTERNAL = {
    "i_detect_aligned",
    "i_start_aligned",
    "i_end_aligned",
    "i_settled_aligned",
    "delay_cycles",
    "redetect_t",
    "echo_t",
    "lookback_s",
    "diff_at_detect_kmh_s",
    "ax_at_detect_kmh_s",
    "ap_at_detect_kmh_s",
    "v_pulse_at_detect_mps",
    "residual_at_detect_kmh_s",
    "gyro_bias_rad_s",
    "theta_clipped",
    "end_speed_error_mps",
    "psi0_rad",
    "theta_end_rad",
}


def assert_same(a: Any, b: Any, path: str = "") -> None:
    """Deep equality of stage results: dataclass fields, mappings, sequences, arrays
    (NaN equal to NaN, same dtype), floats (NaN equal to NaN)."""
    assert type(a) is type(b), path
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, path
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), path
    elif isinstance(a, Mapping):
        assert a.keys() == b.keys(), path
        for k in a:
            assert_same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and np.isnan(a):
        assert np.isnan(b), path
    else:
        assert a == b, path


def arrays(x: Any) -> list[np.ndarray]:
    """Every array held (recursively) by a stage result."""
    if isinstance(x, np.ndarray):
        return [x]
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return [a for f in dataclasses.fields(x) for a in arrays(getattr(x, f.name))]
    if isinstance(x, Mapping):
        return [a for v in x.values() for a in arrays(v)]
    if isinstance(x, (list, tuple)):
        return [a for v in x for a in arrays(v)]
    return []


def run_stages(cycles: Cycles, cfg: OdometryConfig, radar: SpeedOnCycles | None) -> tuple[Any, ...]:
    s = align_streams(cycles, cfg)
    g = None if radar is None else align_ground(s, radar, metres_per_pulse(cycles.pulses, cycles.d_pulse))
    d = detect(s, cfg, g)
    eps = find_episodes(s, d, cfg, g)
    watches = tuple(ep.watch for ep in eps)
    odo = assemble(s, d, cfg, eps)
    if g is not None:
        odo = ground_products(s, g, cfg, odo, [ep.i_settled - s.delay for ep in eps])
    return s, g, d, eps, watches, odo


def random_run(
    data: st.DataObject,
) -> tuple[Scenario, OdometryConfig, SpeedOnCycles | None]:
    onset = data.draw(st.floats(12.0, 18.0), label="onset")
    dur = data.draw(st.floats(1.0, 14.0), label="duration")
    factor = data.draw(st.sampled_from([-1.0, 1.0]), label="sign") * data.draw(st.floats(0.05, 0.4), label="depth")
    accel = data.draw(st.floats(-0.3, 0.5), label="accel")
    v0 = data.draw(st.floats(6.0, 20.0), label="v0")
    sc = scenario(
        36.0,
        const(accel),
        v0,
        theta=const(np.arctan(data.draw(st.floats(-25.0, 25.0), label="grade_permil") / 1000)),
        slip=slip_pulse(onset, dur, factor, edge=data.draw(st.floats(0.2, 1.0), label="edge")),
        cab=data.draw(st.sampled_from([1, -1]), label="cab"),
        ax_noise_kmh_s=0.1,
        seed=data.draw(st.integers(0, 2**16), label="seed"),
    )
    if data.draw(st.booleans(), label="imu gaps"):
        gaps = np.random.default_rng(1).random(sc.cycles.n) < 0.03
        for c in sc.cycles.imu.values():
            c[gaps] = np.nan
    cfg = replace(
        CFG,
        residual_threshold_kmh_s=data.draw(st.sampled_from([0.0, CFG.residual_threshold_kmh_s]), label="residual"),
        failsafe_watch_s=data.draw(st.sampled_from([0.0, CFG.failsafe_watch_s]), label="watch"),
    )
    radar = None
    if data.draw(st.booleans(), label="radar"):
        v = sc.v_true * (1.0 + 0.005 * np.random.default_rng(2).standard_normal(sc.v_true.size))
        if data.draw(st.booleans(), label="radar gap"):
            v[(sc.cycles.t > onset) & (sc.cycles.t < onset + 1.5)] = np.nan
        radar = SpeedOnCycles(v, np.maximum(0.005 * np.abs(v), 0.02), "radar", signed_mps=v * sc.cycles.cab)
        cfg = replace(cfg, wheel_calibration=data.draw(st.booleans(), label="calibration"))
    return sc, cfg, radar


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_stages_are_pure(data: st.DataObject) -> None:
    sc, cfg, radar = random_run(data)
    cycles_before = copy.deepcopy(sc.cycles)
    radar_before = copy.deepcopy(radar)
    first = run_stages(sc.cycles, cfg, radar)
    s, g, d, eps, watches, odo = first
    kept = copy.deepcopy((s, g, d, eps, watches))
    # the same inputs again, and each later stage run again on the first run's results
    assert_same(run_stages(sc.cycles, cfg, radar), first)
    eps_again = find_episodes(s, d, cfg, g)
    assert_same(eps_again, eps)
    again = assemble(s, d, cfg, eps_again)
    if g is not None:
        again = ground_products(s, g, cfg, again, [ep.i_settled - s.delay for ep in eps_again])
    assert_same(again, odo)
    assert_same(correct_odometry(sc.cycles, cfg, radar), odo)
    # nothing was changed: inputs, earlier results
    assert_same(sc.cycles, cycles_before)
    assert_same(radar, radar_before)
    assert_same((s, g, d, eps, watches), kept)
    # frozen results with read-only arrays (the output Odometry itself stays writable)
    for part in (s, d, *eps, *(w for w in watches if w is not None), *([] if g is None else [g])):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(part, dataclasses.fields(part)[0].name, None)
        assert not any(a.flags.writeable for a in arrays(part))
    assert odo.d.flags.writeable and odo.allowance.flags.writeable
    assert isinstance(odo.diagnostics, OdometryDiagnostics)
    assert len(odo.diagnostics.episodes) == len(odo.episodes) == len(eps)


def test_random_run_kinds_give_readhered_and_failsafe_episodes() -> None:
    """The purity test above is only worth something if its runs have episodes: one of its
    kind, a 30 % slip of 3 s, gives one re-adhered and a 14 s slide a fail-safe."""
    for dur, factor, failsafe in ((3.0, 0.3, False), (14.0, -0.3, True)):
        sc = scenario(36.0, const(0.1), 10.0, slip=slip_pulse(15.0, dur, factor), ax_noise_kmh_s=0.1)
        *_, odo = run_stages(sc.cycles, CFG, None)
        assert [e.failsafe for e in odo.episodes[:1]] == [failsafe]
        assert (odo.episodes[0].watch is not None) == failsafe


def test_episode_event_detail_is_its_public_fields() -> None:
    watch = FailsafeWatch(end_t=61.0, allowance_m=3.5, readhered=True, speed_source="inertial")
    ep = SlipEpisode(
        "slide", 41.2, 40.0, 50.0, 400, 500, 180.0, 200.0, 22.8, False, True,
        criterion="residual", start_found=False, theta0_rad=0.01, v0_mps=20.0, watch=watch,
    )  # fmt: skip
    detail = ep.event_detail()
    assert detail["duration_s"] == 10.0 and detail["t_detect"] == 41.2 and detail["t_end"] == 50.0
    assert detail["criterion"] == "residual" and detail["start_found"] is False
    assert (detail["watch_end_t"], detail["watch_allowance_m"]) == (61.0, 3.5)
    assert detail["watch_readhered"] is True and detail["watch_speed_source"] == "inertial"
    assert "watch_end_t" not in replace(ep, watch=None).event_detail()
    public = {f.name for f in dataclasses.fields(SlipEpisode)} - {"kind", "t_start", "i_start", "i_end", "watch"}
    assert set(detail) == public | {"duration_s"} | {f"watch_{f.name}" for f in dataclasses.fields(FailsafeWatch)}
    with pytest.raises(dataclasses.FrozenInstanceError):
        ep.t_end = 0.0  # type: ignore[misc]


# --------------------------------------------------------------------------- pipeline events
@pytest.fixture(scope="module")
def slips_run(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> PipelineResult:
    """The sample run with slips, without its radar: two of its episodes fail safe."""
    folder = tmp_path_factory.mktemp("slips") / "sim-d-slips"
    shutil.copytree(SAMPLE_LOGS / "sim-d-slips", folder, ignore=shutil.ignore_patterns("radar*"))
    return run_pipeline(read_run(folder), read_network(sample_db))


@pytest.fixture(scope="module")
def slips_radar_run(sample_db: Path) -> PipelineResult:
    """The sample run with slips and its radar stream."""
    return run_pipeline(read_run(SAMPLE_LOGS / "sim-d-slips"), read_network(sample_db))


def test_no_internal_key_in_the_slip_events_with_radar(slips_radar_run: PipelineResult) -> None:
    """With the radar the same holds; its two 9–9.4 s slips re-adhere (no fail-safe)."""
    odo = slips_radar_run.odometry
    assert all(e.speed_source == "radar" and not e.failsafe for e in odo.episodes)
    assert slips_radar_run.summary["n_failsafe"] == 0
    assert slips_radar_run.summary["radar"]["source"] == "radar"
    assert_public_events(slips_radar_run)


def test_no_internal_key_in_the_slip_events(slips_run: PipelineResult) -> None:
    assert "radar" not in slips_run.summary and "wheel_calibration" not in slips_run.summary
    assert_public_events(slips_run)
    assert any(e.failsafe for e in slips_run.odometry.episodes)


def assert_public_events(run: PipelineResult) -> None:
    odo = run.odometry
    ev = run.events[run.events["type"].isin(["slip", "slide"])]
    assert len(ev) == len(odo.episodes) >= 2
    assert any(e.readhered for e in odo.episodes)
    internal = LEGACY_INTERNAL | {f.name for f in dataclasses.fields(EpisodeDiagnostics)}
    internal |= {f.name for f in dataclasses.fields(OdometryDiagnostics)}
    by_t = {e.t_start: e for e in odo.episodes}
    for t, text in zip(ev["t"], ev["detail"], strict=True):
        detail = json.loads(text)
        assert not internal & set(detail), sorted(internal & set(detail))
        assert detail == jsonable(by_t[float(t)].event_detail(), DETAIL_DIGITS)
    for summary_ep in run.summary["episodes"]:
        assert not internal & set(summary_ep)
