"""The IF simulator by hand: one scatterer's echo (amplitude, phase), the Doppler sign of
forward and backward motion, clutter power against the footprint integral, and existing
simulated runs unchanged while ``sensors.radar_if`` is off."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from dbtools.network import Network
from fieldlogs.runs.handle import read_run
from fieldlogs.simulate.radar import Ground, echo, ground, reference_power, view
from fieldlogs.simulate.scenario import load_scenario, scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.logs import RADAR_IF

C = 299_792_458.0
CFG = load_scenario().radar_if  # h 0.8 m, depression 45°, β 7.5° / 3°


def one(x: float, y: float = 0.0, z: float = 0.0, amp: complex = 1.0) -> Ground:
    return Ground(np.array([x]), np.array([y]), np.array([z]), np.array([amp], dtype=np.complex128))


def test_one_scatterer_on_the_beam_axis_by_hand() -> None:
    # 0.8 m ahead, 0.8 m below: R = 0.8·√2 = 1.13137 m, δ = 45° = axis → g = 1,
    # amplitude sin δ / R² = 0.70711 / 1.28 = 0.55243, phase −4π·f0·R/c
    v = view(CFG)
    z = echo(one(10.8), np.array([10.0]), np.array([0.8]), +1, CFG.f0_hz, CFG, v)[0]
    r = 0.8 * math.sqrt(2)
    assert abs(z) == pytest.approx(0.55243, abs=1e-5)
    assert np.angle(z * np.exp(4j * math.pi * CFG.f0_hz * r / C)) == pytest.approx(0.0, abs=1e-6)


def test_off_axis_scatterer_follows_the_two_way_pattern() -> None:
    # at the elevation half-width (δ = 52.5°) the two-way amplitude is one half; at 3° azimuth too
    v = view(CFG)
    x = 0.8 / math.tan(math.radians(52.5))
    z = abs(echo(one(x), np.array([0.0]), np.array([0.8]), +1, CFG.f0_hz, CFG, v)[0])
    r = 0.8 / math.sin(math.radians(52.5))
    # the pattern is Gaussian in sin ε: g = exp(−ln2·(sin 7.5°/sin 7.5°)²) = 0.5
    assert z == pytest.approx(0.5 * math.sin(math.radians(52.5)) / r**2, rel=1e-9)
    assert abs(echo(one(x), np.array([0.0]), np.array([0.8]), -1, CFG.f0_hz, CFG, v)[0]) == 0.0  # behind


@pytest.mark.parametrize(("speed", "look", "sign"), [(10.0, 1, 1), (-10.0, 1, -1), (10.0, -1, -1)])
def test_doppler_sign_of_forward_and_backward_motion(speed: float, look: int, sign: int) -> None:
    # the antenna moves at `speed` along σ; the scatterer 0.8 m in front of the beam
    t = np.arange(200) * 1e-4
    pos = np.asarray(speed * t, dtype=np.float64)
    g = one(look * 0.8)
    z = echo(g, pos, np.full(len(t), 0.8), look, CFG.f0_hz, CFG, view(CFG))
    f = np.angle(z[1:] * np.conj(z[:-1])) / (2 * math.pi * 1e-4)
    # ahead distance x = 0.8 − look·speed·t; closing rate (x/R)·look·speed, f_d = 2·rate/λ:
    # + when approaching (1135 Hz at 45°, 10 m/s)
    tm = 0.5 * (t[1:] + t[:-1])
    x = 0.8 - look * speed * tm
    want = 2 * (x / np.hypot(x, 0.8)) * look * speed / (C / CFG.f0_hz)
    assert np.all(np.sign(f) == sign)
    assert f == pytest.approx(want, rel=2e-3)
    assert abs(want[0]) == pytest.approx(1135.0, abs=1.0)


def test_clutter_power_matches_the_footprint_integral() -> None:
    cfg = replace(CFG, strong_per_m=0.0, ballast_roughness_m=0.0, scatterers_per_m2=2000.0)

    class Flat:
        def km_at(self, s: np.ndarray) -> np.ndarray:
            return s

    v = view(cfg)
    g = ground(cfg, Flat(), (0.0, 60.0), v.y_max, np.random.default_rng(3))  # type: ignore[arg-type]
    pos = np.linspace(2.0, 55.0, 4000)
    z = echo(g, pos, np.full(len(pos), cfg.height_m), +1, cfg.f0_hz, cfg, v)
    assert np.mean(np.abs(z) ** 2) == pytest.approx(reference_power(cfg), rel=0.1)


def _short(extra: dict[str, object]) -> dict[str, object]:
    base = {"route": {"track": "D", "path_km_m": [3000.0, 3250.0]}, "slip": {"slips": 0, "slides": 0}}
    return {**base, **extra}


def test_off_means_bit_identical_and_on_changes_no_other_stream(demo_net: Network) -> None:
    plain = simulate_run(demo_net, scenario_from_dict(_short({})), seed=11)
    knobs = simulate_run(demo_net, scenario_from_dict(_short({"radar_if": {"snr_db": 12.0}})), seed=11)
    on = simulate_run(demo_net, scenario_from_dict(_short({"sensors": {"radar_if": True}})), seed=11)
    assert plain.meta.to_json() == knobs.meta.to_json() and "radar" not in plain.meta.extra
    for name, frame in plain.streams.items():
        assert frame.equals(knobs.streams[name]) and frame.equals(on.streams[name]), name
    assert set(on.streams) == set(plain.streams) | {"radar_if"}
    d = on.streams["radar_if"]
    assert list(d.columns) == RADAR_IF.column_names
    assert d["i1"].dtype == np.float32 and d["t"].dtype == np.float64
    assert (
        np.allclose(np.diff(d["t"].to_numpy()), 1e-4) and d["t"].iloc[-1] <= plain.meta.extra["sim_truth"]["duration_s"]
    )
    assert float(d[["i1", "q1", "i2", "q2"]].abs().max().max()) <= 1.0
    assert on.meta.extra["radar"]["f0_hz"] == 24.06e9 and on.meta.extra["radar"]["looks_toward"] == "F"


def test_simulated_run_reads_back_with_its_radar(radar_run: object) -> None:
    run = read_run(radar_run)  # type: ignore[arg-type]
    assert run.radar is not None and run.radar.height_m == 0.8
    assert run.findings == [] and run.stream("radar_if") is not None
