"""Eq. 1 / eq. 2 with known geometry: lines made by hand from V_G, h and depressions θ_m
(V_m = V_G·cos θ_m, R_m = h/sin θ_m), not by the simulator."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.solve import classify, eq2_closed_form, fit_frames, range_gate
from fieldlogs.radar.spectrum import Lines
from schemas.radar import RadarParams

P = RadarParams(24.06e9, 12.75e6, 50e-6, 0.307, 0.8, 45.0, 7.5, 3.0)


def lines_from(v_g: float, deg: list[float], p: RadarParams = P, snr: float = 1e4, frame: int = 0) -> Lines:
    th = np.radians(deg)
    v_m = v_g * np.cos(th)
    fd = 2 * v_m / p.wavelength_m
    n = len(deg)
    return Lines(
        frame=np.full(n, frame, dtype=np.int64),
        bin=np.round(fd / 3.255).astype(np.int64),
        fd_hz=fd,
        v_m=v_m,
        range_m=p.height_m / np.sin(th),
        snr=np.full(n, snr),
        snr_mirror=np.zeros(n),
    )


def cat(*parts: Lines) -> Lines:
    return Lines(*(np.concatenate([getattr(x, f) for x in parts]) for f in Lines.__dataclass_fields__))


def test_eq1_holds_and_eq2_closed_form_is_exact_by_hand() -> None:
    # V_G = 20 m/s, h = 0.8 m: θ = 40° → V_m = 15.321 m/s, R = 1.2446 m; θ = 50° → 12.856, 1.0443
    lines = lines_from(20.0, [40.0, 50.0])
    assert lines.v_m == pytest.approx([15.3209, 12.8558], abs=1e-4)
    assert lines.range_m == pytest.approx([1.24458, 1.04433], abs=1e-5)
    s, u = (0.8 / lines.range_m) ** 2, lines.v_m**2
    assert s + u / 20.0**2 - 1 == pytest.approx([0.0, 0.0], abs=1e-12)  # eq. 1
    w = eq2_closed_form(lines.frame, u, s, np.ones(2), 1)
    assert 1 / math.sqrt(w[0]) == pytest.approx(20.0, rel=1e-12)  # eq. 2


def test_fit_recovers_the_ground_speed_and_direction() -> None:
    fit = fit_frames(lines_from(20.0, [38.0, 41.0, 45.0, 48.0, 52.0]), 1, P, RadarConfig())
    assert fit.v[0] == pytest.approx(20.0, rel=1e-9)
    assert fit.v_eq2[0] == pytest.approx(20.0, rel=1e-9)
    assert fit.direction[0] == 1 and fit.n_used[0] == 5 and fit.consistency[0] == pytest.approx(1.0)
    back = fit_frames(lines_from(-20.0, [38.0, 41.0, 45.0, 48.0, 52.0]), 1, P, RadarConfig())
    assert back.v[0] == pytest.approx(20.0, rel=1e-9) and back.direction[0] == -1


def test_naive_single_peak_is_biased_by_the_beam_spread() -> None:
    # strongest line at θ = 52° while the axis is 45°: v = V·cos 52°/cos 45° = 0.8707·V
    lines = lines_from(20.0, [40.0, 45.0, 52.0])
    lines.snr[2] = 1e6
    fit = fit_frames(lines, 1, P, RadarConfig())
    assert fit.v_naive[0] == pytest.approx(20.0 * math.cos(math.radians(52)) / math.cos(math.radians(45)), rel=1e-9)
    assert fit.v[0] == pytest.approx(20.0, rel=1e-9)


def test_frames_are_solved_independently() -> None:
    lines = cat(lines_from(5.0, [40.0, 50.0], frame=0), lines_from(25.0, [42.0, 47.0], frame=2))
    fit = fit_frames(lines, 3, P, RadarConfig())
    assert fit.v[0] == pytest.approx(5.0) and fit.v[2] == pytest.approx(25.0)
    assert np.isnan(fit.v[1]) and fit.n_lines.tolist() == [2, 0, 2]


def test_outlier_range_is_left_out_without_bias() -> None:
    good = lines_from(15.0, [38.0, 40.0, 42.0, 44.0, 46.0, 48.0, 50.0, 52.0])
    bad = lines_from(15.0, [45.0])
    bad.range_m[:] = 1.40  # inside the ground gate but 0.27 m off eq. 1
    fit = fit_frames(cat(good, bad), 1, P, RadarConfig())
    assert fit.n_used[0] == 8
    assert fit.v[0] == pytest.approx(15.0, rel=1e-6)


def test_ground_gate_and_alias_classification() -> None:
    r0, r1 = range_gate(P, 2.0)  # θ0 ± 2·7.5° = 30° … 60°: h/sin 60° … h/sin 30°
    assert (r0, r1) == pytest.approx((0.8 / math.sin(math.radians(60)), 1.6))
    lines = lines_from(10.0, [45.0, 45.0, 45.0])
    lines.range_m[1] += P.r_max_m / 2  # what an aliased line looks like
    lines.range_m[2] = 8.0  # neither
    ground, alias = classify(lines, P, RadarConfig())
    assert ground.tolist() == [True, False, False]
    assert alias.tolist() == [False, True, False]


def test_uncertainty_shrinks_with_snr_and_lines() -> None:
    rng = np.random.default_rng(1)

    def sigma(snr: float, n: int) -> float:
        lines = lines_from(20.0, list(np.linspace(36.0, 54.0, n)), snr=snr)
        lines.range_m[:] += rng.normal(0, P.r_max_m / (2 * np.pi) / math.sqrt(snr), n)
        return float(fit_frames(lines, 1, P, RadarConfig()).sigma[0])

    assert sigma(1e5, 30) < sigma(1e3, 30)
    assert sigma(1e4, 60) < sigma(1e4, 6)


@settings(max_examples=60, deadline=None)
@given(
    v=st.floats(0.3, 40.0),
    h=st.floats(0.3, 1.5),
    dep=st.floats(25.0, 65.0),
    offsets=st.lists(st.floats(-7.0, 7.0), min_size=1, max_size=20),
)
def test_exact_lines_give_the_exact_speed(v: float, h: float, dep: float, offsets: list[float]) -> None:
    p = RadarParams(24.06e9, 12.75e6, 50e-6, 0.307, h, dep, 7.5, 3.0)
    fit = fit_frames(lines_from(v, [dep + o for o in offsets], p), 1, p, RadarConfig())
    assert fit.v[0] == pytest.approx(v, rel=1e-7)
    assert fit.v_eq2[0] == pytest.approx(v, rel=1e-7)


def test_beam_core_narrows_below_core_speed_by_hand() -> None:
    # θ0 = 45°, β_e = 7.5°, core 1.5 half-widths at and above core_speed_mps = 9 m/s,
    # 1.5·V/9 below, never under 0.5: 20 m/s → ±11.25°; 4.5 m/s → ±5.625°; 1 m/s → ±3.75°
    cfg = RadarConfig()
    assert (cfg.core_beamwidths, cfg.core_speed_mps, cfg.core_min_beamwidths) == (1.5, 9.0, 0.5)
    # at 4.5 m/s a line at 39.5° is inside the core, one at 39.2° outside (edge 39.375°)
    inside = lines_from(4.5, [39.5, 45.0])
    inside.range_m[0] += 0.05  # an off line in the core pulls the fit
    assert fit_frames(inside, 1, P, cfg).v[0] != pytest.approx(4.5, rel=1e-4)
    outside = lines_from(4.5, [39.2, 45.0])
    outside.range_m[0] += 0.05  # outside the core: left out, the fit is exact
    fit = fit_frames(outside, 1, P, cfg)
    assert fit.v[0] == pytest.approx(4.5, rel=1e-9) and fit.n_used[0] == 1
    # at 20 m/s the same 39.2° line is inside (edge 33.75°)
    fast = lines_from(20.0, [39.2, 45.0])
    fast.range_m[0] += 0.05
    assert fit_frames(fast, 1, P, cfg).n_used[0] == 2


def test_walking_pace_edge_lines_pulled_toward_the_centre_are_left_out() -> None:
    # 1.5 m/s: core ±3.75°. Edge lines with ranges pulled toward the beam centre as the
    # spectrum's 1.1° bins make them (shallow lines short, steep lines long: bench/NOTES.md)
    # would read the speed high; in the narrowed core only the exact central lines count.
    v = 1.5
    core = lines_from(v, [42.0, 43.5, 45.0, 46.5, 48.0])
    edge = lines_from(v, [34.0, 35.5, 37.0, 55.0])
    edge.range_m[:] += np.array([-0.045, -0.03, -0.018, 0.008])
    lines = cat(core, edge)
    fit = fit_frames(lines, 1, P, RadarConfig())
    assert fit.v[0] == pytest.approx(v, rel=1e-9) and fit.n_used[0] == 5
    wide = fit_frames(lines, 1, P, RadarConfig(core_speed_mps=0.0))  # the fixed ±1.5 half-width core
    assert wide.n_used[0] == 9 and wide.v[0] > v * 1.002


def test_frame_without_a_line_in_the_narrowed_core_uses_the_widest() -> None:
    # 1.5 m/s, lines only at 38° and 52° (outside ±3.75°, inside ±11.25°): still a speed
    fit = fit_frames(lines_from(1.5, [38.0, 52.0]), 1, P, RadarConfig())
    assert fit.v[0] == pytest.approx(1.5, rel=1e-9) and fit.n_used[0] == 2
