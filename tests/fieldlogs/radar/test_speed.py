"""End to end on hand-made samples: speed and sign, each frame status, block independence."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.speed import RadarSpeed, lowest_speed_mps, process_if
from schemas.enums import RadarStatus
from tests.fieldlogs.radar.signals import TABLE1, C, ground_if, reflectors_if

DEGREES = list(np.arange(38.0, 52.5, 1.5))


def run(d: dict[str, np.ndarray], p=TABLE1, cfg: RadarConfig = RadarConfig()) -> RadarSpeed:  # type: ignore[no-untyped-def]
    return process_if(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], p, cfg)


def test_ground_lines_give_the_speed_signed_toward_f() -> None:
    res = run(ground_if(TABLE1, 20.0, DEGREES, noise=3e-3))
    c = res.columns
    assert list(c["status"]) == ["ok", "ok"]
    # 30 dB per sample: ranges good to ~2 mm, V_G to ~0.05 %; σ assumes ≥ 1 cm per line
    assert np.all(np.abs(c["speed_mps"] - 20.0) < 0.03)
    assert np.all((c["sigma_mps"] > np.abs(c["speed_mps"] - 20.0)) & (c["sigma_mps"] < 0.1))
    assert c["n_used"].tolist() == [len(DEGREES)] * 2 and c["n_alias"].tolist() == [0, 0]
    assert c["v_eq2_mps"] == pytest.approx([20.0, 20.0], abs=0.05)
    back = run(ground_if(TABLE1, -20.0, DEGREES)).columns
    assert back["speed_mps"] == pytest.approx([-20.0, -20.0], abs=0.002)
    # a radar looking toward the R end sees the ground recede when the vehicle moves toward F
    rear = replace(TABLE1, looks_toward="R")
    assert run(ground_if(rear, -20.0, DEGREES), rear).columns["speed_mps"] == pytest.approx([20.0, 20.0], abs=0.002)


def test_naive_speed_by_hand() -> None:
    # the strongest line at 50° while the axis is 45°: v = 20·cos 50°/cos 45° = 18.18 m/s
    amps = [0.01] * len(DEGREES)
    amps[DEGREES.index(50.0)] = 0.2
    c = run(ground_if(TABLE1, 20.0, DEGREES, amp=amps)).columns
    assert c["v_naive_mps"] == pytest.approx([18.182] * 2, abs=0.005)
    assert c["speed_mps"] == pytest.approx([20.0] * 2, abs=0.003)


def test_standstill_and_no_reflections() -> None:
    still = run(reflectors_if(TABLE1, [], [], static=0.05 + 0.02j, noise=1e-3, frames=3)).columns
    assert list(still["status"]) == [RadarStatus.STANDSTILL.value] * 3
    assert still["speed_mps"].tolist() == [0.0] * 3
    v_min = lowest_speed_mps(TABLE1, RadarConfig())
    # 3 bins of 10 kHz/3072 at the beam edge 37.5°: 3·3.255·λ/2 / cos 37.5° = 0.0767 m/s
    assert v_min == pytest.approx(3 * 10_000 / 3072 * TABLE1.wavelength_m / 2 / math.cos(math.radians(37.5)))
    assert still["sigma_mps"] == pytest.approx([v_min] * 3)
    dark = run(reflectors_if(TABLE1, [], [], noise=1e-3, frames=2)).columns
    assert list(dark["status"]) == [RadarStatus.NO_REFLECTIONS.value] * 2
    assert np.isnan(dark["speed_mps"]).all()
    # a line, but at 6 m: nothing at a ground range
    far = run(reflectors_if(TABLE1, [800.0], [6.0], static=0.05)).columns
    assert list(far["status"]) == [RadarStatus.NO_REFLECTIONS.value] * 2


def test_speed_beyond_the_doppler_nyquist_is_flagged_not_reported() -> None:
    # V_G = 50 m/s: V_m = 50·cos θ from 39.4 to 30.8 m/s, mostly above Vmax = 31.15 m/s
    c = run(ground_if(TABLE1, 50.0, DEGREES)).columns
    assert list(c["status"]) == [RadarStatus.ALIASED.value] * 2
    assert np.isnan(c["speed_mps"]).all() and (c["n_alias"] >= 3).all()
    # 42 m/s: nothing wraps at 38–52°, but the beam's half-power edge does (42·cos 37.5° = 33.3 > 31.15)
    c = run(ground_if(TABLE1, 42.0, DEGREES[2:])).columns
    assert list(c["status"]) == [RadarStatus.ALIASED.value] * 2


def test_missing_samples_make_low_quality_frames() -> None:
    d = ground_if(TABLE1, 10.0, DEGREES, frames=3)
    keep = np.ones(len(d["t"]), dtype=bool)
    keep[3070 + 100 : 3070 + 700] = False  # 20 % of frame 1
    res = run({k: v[keep] for k, v in d.items()})
    assert list(res.columns["status"]) == ["ok", "low_quality", "ok"]
    assert res.columns["valid_share"][1] == pytest.approx(1 - 600 / 3070)


def test_vibration_sidebands_at_rest_are_standstill_not_a_speed() -> None:
    # a static echo whose range vibrates 1 mm at 9 Hz: lines at ±9 Hz, ±18 Hz … on both sides
    p = TABLE1
    n = 2 * p.samples_per_frame
    t = np.arange(n) * 2 * p.t_pri_s
    d = {"t": t}
    rng = np.random.default_rng(2)
    for k, (f, dt) in enumerate(((p.f0_hz, 0.0), (p.f0_hz + p.delta_f_hz, p.t_pri_s)), start=1):
        r = 1.1 + 0.001 * np.sin(2 * np.pi * 9.0 * (t + dt))
        noise = 1.6e-3 * (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2)  # 30 dB below
        z = 0.05 * np.exp(-4j * np.pi * f * r / C) + noise
        d[f"i{k}"], d[f"q{k}"] = z.real.astype(np.float32), z.imag.astype(np.float32)
    c = run(d).columns
    assert list(c["status"]) == [RadarStatus.STANDSTILL.value] * 2
    assert c["speed_mps"].tolist() == [0.0, 0.0] and (c["n_lines"] >= 2).all()


def test_one_sided_weak_sideband_is_checked_against_its_mirror_bin() -> None:
    # +18 Hz at SNR 40 (16 dB), its mirror −18 Hz 7 dB weaker, below the 11.4 dB threshold:
    # one line only, but no translation (consistency (40 − 8)/(40 + 8) = 0.67 < 0.8)
    p = TABLE1
    floor_amp = 3e-4  # noise per sample; a bin's noise power ≈ σ²·Σw² = σ²·3N/8
    bin_noise = floor_amp**2 * 3 * p.samples_per_frame / 8
    tone = math.sqrt(40 * bin_noise) / (p.samples_per_frame / 2)  # Hann peak gain N/2
    h = p.height_m / math.sin(math.radians(45))
    d = reflectors_if(p, [18.0, -18.0], [h, h], amp=[tone, 0.45 * tone], noise=floor_amp, static=0.05, frames=3)
    c = run(d).columns
    assert (c["n_lines"] == 1).any()
    assert list(c["status"]) == [RadarStatus.STANDSTILL.value] * 3


def test_slow_motion_is_not_taken_for_vibration() -> None:
    c = run(ground_if(TABLE1, 0.25, [40.0, 45.0, 50.0], static=0.05, noise=1e-3)).columns
    assert list(c["status"]) == ["ok", "ok"] and c["speed_mps"] == pytest.approx([0.25, 0.25], abs=0.01)


def test_blocks_do_not_change_the_result() -> None:
    d = ground_if(TABLE1, 12.0, DEGREES, frames=5, noise=3e-3, seed=4)
    a = run(d, cfg=RadarConfig(block_frames=2)).to_frame()
    b = run(d, cfg=RadarConfig(block_frames=256)).to_frame()
    assert a["status"].equals(b["status"]) and a["n_used"].equals(b["n_used"])
    num = [c for c in a.columns if c != "status"]
    # batched float32 FFTs may round the last bit differently
    assert np.allclose(a[num].to_numpy(float), b[num].to_numpy(float), rtol=1e-5, equal_nan=True)


def test_empty_input_gives_no_frame() -> None:
    empty = np.zeros(0)
    res = process_if(empty, empty, empty, empty, empty, TABLE1)
    assert len(res) == 0 and list(res.to_frame().columns)[:3] == ["t", "speed_mps", "sigma_mps"]
    assert res.summary()["frames"] == 0


def test_single_scatterer_at_walking_pace_by_hand() -> None:
    # 1.5 m/s toward where the radar looks, one reflector at the beam axis 45°, h = 0.8 m:
    # λ = c/f0 = 299792458/24.06e9 = 0.0124602 m, f_d = 2·1.5·cos 45°/λ = 170.25 Hz
    # (52.3 bins of 3.2552 Hz), R = 0.8/sin 45° = 1.13137 m → V_G = 1.5 m/s by eq. 1
    fd, r = 2 * 1.5 * math.cos(math.radians(45.0)) / (C / 24.06e9), 0.8 / math.sin(math.radians(45.0))
    assert fd == pytest.approx(170.25, abs=0.01) and r == pytest.approx(1.13137, abs=1e-5)
    c = run(reflectors_if(TABLE1, [fd], [r], noise=3e-3)).columns
    assert list(c["status"]) == ["ok", "ok"] and c["n_used"].tolist() == [1, 1]
    assert c["speed_mps"] == pytest.approx([1.5, 1.5], abs=0.002)
    assert np.all(np.abs(c["speed_mps"] - 1.5) <= 3 * c["sigma_mps"])
