"""Pseudorange multipath off a surface beside the track (fieldlogs.simulate.gnss.reflection):
hand-computed geometry (sign, magnitude, elevation dependence), the tracking-loop errors and
the simulator's use of them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fieldlogs.gnss.constants import WEEK_S
from fieldlogs.simulate.gnss.constellation import constellation_nav
from fieldlogs.simulate.gnss.observations import Corridor, ErrorSpec, ReceiverSpec, simulate
from fieldlogs.simulate.gnss.reflection import (
    HALF_SPACING_M,
    LAMBDA_L1_M,
    Reflectors,
    amplitude,
    carrier_error,
    cn0_change,
    code_error,
    excess_path,
    phase_walk,
)
from fieldlogs.simulate.gnss.scenario import run_profile, synthetic_track, trajectory

T0 = 2300 * WEEK_S + 5 * 3600.0
UP = 3.8  # antenna above the rail; the surface's top is 8 m: 4.2 m above the antenna


def _delta(side: float, d: float, el_deg: float, rel_az_deg: float) -> float:
    return float(excess_path(np.array(side), np.array(d), np.radians(el_deg), np.radians(rel_az_deg), UP))


def test_excess_path_hand_computed() -> None:
    # surface 4 m to the left; a satellite straight to the right (A − ψ = 90°, cos α = 1)
    assert _delta(1, 4.0, 30.0, 90.0) == pytest.approx(2 * 4 * math.cos(math.radians(30)))  # 6.928 m
    # specular point d·tan E / cos α above the antenna: 4·tan 45° = 4 m ≤ 4.2 m reflects, 4·tan 60° does not
    assert _delta(1, 4.0, 45.0, 90.0) == pytest.approx(8 * math.sqrt(0.5))  # 5.657 m
    assert _delta(1, 4.0, 60.0, 90.0) == 0.0
    # obliquely (A − ψ = 150°, cos α = ½): at 20° the point is 4·0.364/0.5 = 2.91 m up, at 30° 4.62 m
    assert _delta(1, 4.0, 20.0, 150.0) == pytest.approx(2 * 4 * math.cos(math.radians(20)) * 0.5)  # 3.759 m
    assert _delta(1, 4.0, 30.0, 150.0) == 0.0
    # a satellite on the surface's own side (left), none, or the surface inside the loading gauge
    assert _delta(1, 4.0, 20.0, -90.0) == 0.0
    assert _delta(-1, 4.0, 20.0, -90.0) == pytest.approx(8 * math.cos(math.radians(20)))
    assert _delta(0, 4.0, 20.0, 90.0) == 0.0
    assert _delta(1, 1.0, 20.0, 90.0) == 0.0


def test_excess_path_is_positive_and_falls_with_elevation() -> None:
    el = np.radians(np.arange(1.0, 90.0, 1.0))
    delta = excess_path(np.ones_like(el), np.full_like(el, 4.0), el, np.full_like(el, np.pi / 2), UP)
    on = delta > 0
    assert on[0] and not on[-1]
    # reflected up to E = atan(4.2 / 4) = 46.4°, above it none
    assert np.degrees(el[on]).max() == 46.0 and np.degrees(el[~on]).min() == 47.0
    assert np.all(np.diff(delta[on]) < 0)  # 2 d cos E


def test_code_carrier_and_cn0_of_the_two_path_signal() -> None:
    # a = 0.5, Δ = 6 m: in phase a·Δ/(1 + a) = +2 m (late), out of phase −a·Δ/(1 − a) = −6 m,
    # in quadrature Δ·a²/(1 + a²) = 1.2 m
    assert float(code_error(np.array(6.0), np.array(0.5), np.array(0.0))) == pytest.approx(2.0)
    assert float(code_error(np.array(6.0), np.array(0.5), np.array(np.pi))) == pytest.approx(-6.0)
    assert float(code_error(np.array(6.0), np.array(0.5), np.array(np.pi / 2))) == pytest.approx(1.2)
    # beyond half the correlator spacing (0.05 · 293.05 m = 14.65 m) the envelope is flat
    assert HALF_SPACING_M == pytest.approx(14.6526, abs=1e-4)
    assert float(code_error(np.array(40.0), np.array(0.5), np.array(0.0))) == pytest.approx(HALF_SPACING_M / 3)
    # zero mean over the phase for a < 1: a bias of either sign, not a constant offset
    theta = np.linspace(0.0, 2 * np.pi, 4001)[:-1]
    assert float(np.mean(code_error(np.full_like(theta, 6.0), np.full_like(theta, 0.5), theta))) == pytest.approx(
        0.0, abs=1e-9
    )
    # carrier: atan2(0.5, 1)·λ/2π = 0.4636 rad of a 19.03 cm cycle = 1.404 cm; at most asin(a)·λ/2π
    assert float(carrier_error(np.array(0.5), np.array(np.pi / 2))) == pytest.approx(
        0.463648 * LAMBDA_L1_M / (2 * np.pi)
    )
    assert np.abs(carrier_error(np.full_like(theta, 0.5), theta)).max() == pytest.approx(
        math.asin(0.5) * LAMBDA_L1_M / (2 * np.pi), rel=1e-5
    )
    # C/N0: 20·log10 1.5 = +3.52 dB in phase, 20·log10 0.5 = −6.02 dB out of phase
    assert float(cn0_change(np.array(0.5), np.array(0.0))) == pytest.approx(3.5218, abs=1e-4)
    assert float(cn0_change(np.array(0.5), np.array(np.pi))) == pytest.approx(-6.0206, abs=1e-4)


def test_amplitude_from_the_knob() -> None:
    a = amplitude(np.array([1.5, -1.5, 2.5, 2.5]), np.array([4.0, 4.0, 4.0, 1.0]))
    assert a.tolist() == pytest.approx([0.375, 0.375, 0.5, 0.0])  # 2.5/4 = 0.625 capped at 0.5


def test_phase_decorrelates_over_tau() -> None:
    phi = phase_walk(np.random.default_rng(4), 20_000, 4, 1.0, 3.0)
    for lag in (1, 3, 6):
        c = float(np.mean(np.cos(phi[lag:] - phi[:-lag])))
        assert c == pytest.approx(math.exp(-lag / 3.0), abs=0.03)


def test_simulator_adds_the_reflection_where_the_surface_is() -> None:
    """Error-free pseudoranges: with a surface 4 m to the left over s ∈ [1000, 1400) m the ranges
    differ from the run without it by exactly the reflection's code error, only there, only for
    satellites to the right below the surface's top; every other observation is unchanged."""
    tr = synthetic_track()
    s = run_profile(tr.truth.length_m, 120.0, 1.0, 15.0, 800.0, 30000.0)
    traj = trajectory(tr, s, T0, 1.0)
    nav = constellation_nav(T0, T0 + 200.0, seed=1)
    rx = [ReceiverSpec("rx1", 8.0, clock_walk_m=0.0)]
    zero = ErrorSpec(
        sis_sigma_m={"G": 0.0, "E": 0.0, "J": 0.0}, iono_run_sigma=0.0, iono_sat_sigma=0.0, tropo_run_sigma=0.0,
        mp_zenith_m=0.0, mp_low_m=0.0, noise_45_m=0.0, p_nlos=0.0,
    )  # fmt: skip

    def at(s_ant: np.ndarray) -> Reflectors:
        inside = (s_ant >= 1000.0) & (s_ant < 1400.0)
        return Reflectors(inside.astype(float), np.full(s_ant.shape, 4.0), np.where(inside, 0.4, 0.0))

    plain = simulate(traj, nav, rx, Corridor(), seed=3, errors=zero)
    refl = simulate(traj, nav, rx, Corridor(), seed=3, errors=zero, reflectors=at)
    assert plain.obs[["t", "sat"]].equals(refl.obs[["t", "sat"]])
    diff = refl.obs["pseudorange_m"].to_numpy() - plain.obs["pseudorange_m"].to_numpy()
    e = refl.rows["reflection_m"].to_numpy()
    assert diff == pytest.approx(e, abs=1e-6)
    hit = e != 0
    s_ant = np.asarray(np.interp(refl.rows["t"].to_numpy(dtype=float), traj.t, traj.s), dtype=float) + 8.0
    assert hit.sum() > 20 and np.all((s_ant[hit] >= 999.0) & (s_ant[hit] < 1401.0))
    assert refl.rows.loc[hit, "elevation_deg"].max() < 46.4  # atan(4.2/4)
    # |e| ≤ a·Δ/(1 − a) ≤ (0.4/0.6)·2·4 m; both signs occur (in and out of phase)
    assert np.abs(e).max() <= 0.4 / 0.6 * 8.0 and e.min() < 0 < e.max()
    assert (diff[~hit] == 0).all()
