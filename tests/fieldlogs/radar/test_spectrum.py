"""Doppler lines of hand-made reflectors: bin, sign, sub-bin frequency, range from the
f1/f2 phase difference, the T_pri compensation and the aliasing shift (numbers by hand)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.framing import frame_samples
from fieldlogs.radar.spectrum import Lines, detect_lines, fft_length, hann, interpolate, spectra
from schemas.radar import RadarParams
from tests.fieldlogs.radar.signals import TABLE1, C, reflector_if


def lines_of(d: dict[str, np.ndarray], p: RadarParams = TABLE1, cfg: RadarConfig = RadarConfig()) -> Lines:
    fr = frame_samples(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], p)
    return detect_lines(spectra(fr, cfg), p, cfg)


def strongest(lines: Lines, frame: int = 0) -> int:
    idx = np.flatnonzero(lines.frame == frame)
    return int(idx[np.argmax(lines.snr[idx])])


def test_table1_figures() -> None:
    # λ = c/f0 = 12.46 mm; 10 kHz per frequency; N = 0.307 s · 10 kHz = 3070
    assert TABLE1.wavelength_m == pytest.approx(0.0124602, rel=1e-5)
    assert TABLE1.sample_rate_hz == pytest.approx(10_000.0)
    assert TABLE1.samples_per_frame == 3070
    assert TABLE1.speed_resolution_mps * 3.6 == pytest.approx(0.073, abs=5e-4)  # ΔV
    assert TABLE1.v_max_mps * 3.6 == pytest.approx(112.14, abs=0.01)  # Vmax
    assert TABLE1.r_max_m == pytest.approx(11.76, abs=0.005)  # Rmax = c/2Δf
    assert fft_length(3070) == 3072


def test_single_reflector_doppler_bin_and_range_by_hand() -> None:
    # V_m = 10 m/s approaching: f_d = 2·10/λ = 1605.11 Hz; bin = f_d / (10 kHz / 3072) = 493.09
    v_m, r = 10.0, 1.2
    fd = 2 * v_m / TABLE1.wavelength_m
    assert fd == pytest.approx(1605.11, abs=0.01)
    lines = lines_of(reflector_if(TABLE1, fd, r))
    j = strongest(lines)
    assert lines.bin[j] == 493
    assert lines.fd_hz[j] == pytest.approx(fd, abs=0.02 * 10_000 / 3072)  # within 2 % of a bin
    assert lines.v_m[j] == pytest.approx(v_m, abs=0.001)
    # Δφ = 4π·Δf·R/c = 0.6413 rad → R = c·Δφ/(4π·Δf)
    assert 4 * math.pi * 12.75e6 * r / C == pytest.approx(0.6413, abs=1e-4)
    assert lines.range_m[j] == pytest.approx(r, abs=0.002)
    assert set(lines.frame.tolist()) == {0, 1}


def test_receding_reflector_has_negative_doppler() -> None:
    fd = -2 * 7.5 / TABLE1.wavelength_m
    lines = lines_of(reflector_if(TABLE1, fd, 1.5))
    j = strongest(lines)
    assert lines.bin[j] < 0 and lines.v_m[j] == pytest.approx(-7.5, abs=0.001)
    assert lines.range_m[j] == pytest.approx(1.5, abs=0.002)


def test_tpri_offset_of_f2_is_compensated() -> None:
    # at f_d = 4 kHz the f2 sample's Doppler phase advance 2π·f_d·T_pri = 0.4π would move the
    # range by Rmax·f_d·T_pri = 2.35 m if it were not compensated
    fd, r = 4000.0, 1.0
    assert TABLE1.r_max_m * fd * TABLE1.t_pri_s == pytest.approx(2.351, abs=1e-3)
    lines = lines_of(reflector_if(TABLE1, fd, r))
    assert lines.range_m[strongest(lines)] == pytest.approx(r, abs=0.003)


def test_aliased_line_range_is_shifted_by_quarter_wave_of_delta_f() -> None:
    # a true 6 kHz Doppler is sampled at 10 kHz: seen at −4 kHz, compensated with the wrong
    # frequency (off by 10 kHz · 50 µs = half a turn) → range + c/(4·Δf) = + 5.878 m
    fd, r = 6000.0, 1.1
    lines = lines_of(reflector_if(TABLE1, fd, r))
    j = strongest(lines)
    assert lines.fd_hz[j] == pytest.approx(-4000.0, abs=0.1)
    assert C / (4 * 12.75e6) == pytest.approx(5.878, abs=1e-3)
    assert lines.range_m[j] == pytest.approx(r + TABLE1.r_max_m / 2, abs=0.003)


def test_no_line_inside_the_dc_guard_and_none_from_noise() -> None:
    # 3 Hz is inside ±2 bins (6.5 Hz; a reflector at 30 dB SNR per sample); pure noise gives
    # no paired line at P_fa = 1e-6
    assert len(lines_of(reflector_if(TABLE1, 3.0, 1.0, noise=0.1 * 10 ** (-30 / 20)))) == 0
    d = reflector_if(TABLE1, 500.0, 1.0, amp=0.0, noise=0.01, frames=4)
    assert len(lines_of(d)) == 0


@settings(max_examples=40, deadline=None)
@given(delta=st.floats(-0.5, 0.5))
def test_hann_three_bin_interpolation_is_exact_for_a_tone(delta: float) -> None:
    n = 256
    w = hann(n).astype(np.float64)
    k0 = 40
    z = np.exp(2j * np.pi * (k0 + delta) * np.arange(n) / n)
    a = np.abs(np.fft.fft(z * w))
    k = int(np.argmax(a))
    est = k + float(interpolate(np.array([a[k - 1]]), np.array([a[k]]), np.array([a[k + 1]]))[0])
    assert est == pytest.approx(k0 + delta, abs=1e-6)


@settings(max_examples=25, deadline=None)
@given(v_m=st.floats(0.5, 30.0), r=st.floats(0.3, 11.0), sign=st.sampled_from([-1, 1]))
def test_any_reflector_speed_and_range_recovered(v_m: float, r: float, sign: int) -> None:
    fd = sign * 2 * v_m / TABLE1.wavelength_m
    lines = lines_of(reflector_if(TABLE1, fd, r, frames=1))
    j = strongest(lines)
    assert lines.v_m[j] == pytest.approx(sign * v_m, abs=0.002)
    assert lines.range_m[j] == pytest.approx(r, abs=0.003)
