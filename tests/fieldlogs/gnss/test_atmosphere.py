"""Ionosphere and troposphere models: hand-computed values and the independent library."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fieldlogs.gnss import atmosphere as atm
from fieldlogs.gnss.constants import C_MPS, F_L1_HZ, F_L5_HZ

ALPHA = (0.3820e-7, 0.1490e-7, -0.1790e-6, 0.0)
BETA = (0.1430e6, 0.0, -0.3280e6, 0.1130e6)


def _klobuchar_scalar(lat_deg: float, lon_deg: float, az_deg: float, el_deg: float, tow: float) -> float:
    """IS-GPS-200N Figure 20-4 transcribed line by line with scalars (semicircles)."""
    pi = 3.1415926535898
    e = el_deg / 180.0
    a = math.radians(az_deg)
    psi = 0.0137 / (e + 0.11) - 0.022
    phi_i = min(max(lat_deg / 180.0 + psi * math.cos(a), -0.416), 0.416)
    lam_i = lon_deg / 180.0 + psi * math.sin(a) / math.cos(phi_i * pi)
    phi_m = phi_i + 0.064 * math.cos((lam_i - 1.617) * pi)
    t = (4.32e4 * lam_i + tow) % 86400.0
    f = 1.0 + 16.0 * (0.53 - e) ** 3
    amp = max(ALPHA[0] + ALPHA[1] * phi_m + ALPHA[2] * phi_m**2 + ALPHA[3] * phi_m**3, 0.0)
    per = max(BETA[0] + BETA[1] * phi_m + BETA[2] * phi_m**2 + BETA[3] * phi_m**3, 72000.0)
    x = 2.0 * math.pi * (t - 50400.0) / per
    if abs(x) < 1.57:
        return f * (5e-9 + amp * (1 - x**2 / 2 + x**4 / 24))
    return f * 5e-9


@pytest.mark.parametrize(
    ("lat", "lon", "az", "el", "tow"),
    [(40.0, 260.0, 210.0, 20.0, 593100.0), (35.7, 139.7, 90.0, 45.0, 3600.0 * 5), (-20.0, 10.0, 0.0, 80.0, 50400.0)],
)
def test_klobuchar_matches_the_icd_transcription(lat: float, lon: float, az: float, el: float, tow: float) -> None:
    got = atm.klobuchar_s(np.radians(lat), np.radians(lon), np.radians(az), np.radians(el), np.array(tow), ALPHA, BETA)
    assert float(got) == pytest.approx(_klobuchar_scalar(lat, lon, az, el, tow), rel=1e-12)


def test_klobuchar_night_floor_and_frequency() -> None:
    """At night only the 5 ns floor remains, × F; at the zenith F = 1 + 16·0.03³ → 1.4996 m on L1."""
    t_night = np.array(0.0)  # local time ~ 09:20 at 139.7° E is day; use lon 0 at midnight
    got = atm.klobuchar_s(np.radians(0.0), np.radians(0.0), 0.0, np.radians(90.0), t_night, ALPHA, BETA)
    assert C_MPS * float(got) == pytest.approx(C_MPS * 5e-9 * (1 + 16 * 0.03**3), rel=1e-12)
    m = atm.iono_delay_m(
        np.array(["G", "G"]), np.array([F_L1_HZ, F_L5_HZ]), 0.0, 0.0, 0.0, np.radians(90.0), 0.0,
        {"gps_alpha": ALPHA, "gps_beta": BETA},
    )  # fmt: skip
    assert m[1] / m[0] == pytest.approx((F_L1_HZ / F_L5_HZ) ** 2)


def test_galileo_effective_model() -> None:
    lat, lon = np.radians(35.7), np.radians(139.7)
    mu = np.degrees(atm.modip_rad(lat, lon))
    assert 30.0 < float(mu) < 60.0  # mid-latitude Japan: modip ≈ 40–50°
    day = atm.galileo_effective_s(lat, lon, 0.0, np.radians(60.0), np.array(5 * 3600.0), (100.0, 0.0, 0.0))
    night = atm.galileo_effective_s(lat, lon, 0.0, np.radians(60.0), np.array(17 * 3600.0), (100.0, 0.0, 0.0))
    assert float(night) < float(day)
    zero = atm.galileo_effective_s(lat, lon, 0.0, np.radians(60.0), np.array(5 * 3600.0), (0.0, 0.0, 0.0))
    default = atm.galileo_effective_s(lat, lon, 0.0, np.radians(60.0), np.array(5 * 3600.0), (63.7, 0.0, 0.0))
    assert float(zero) == pytest.approx(float(default))  # all-zero coefficients mean Az = 63.7 sfu (ICD)
    assert 1.0 < C_MPS * float(day) < 10.0


def test_saastamoinen_zenith_and_mapping() -> None:
    """Sea level, 45°: zhd = 0.0022768·1013.25 = 2.3070 m; the wet part with 50 % RH at 15 °C ≈ 0.08 m.
    The independent library (gnsstoolbox, Bernese formulation) agrees at the zenith within 1 cm."""
    zhd, zwd = atm.saastamoinen_zenith_m(np.radians(45.0), np.array(0.0))
    assert float(zhd) == pytest.approx(0.0022768 * 1013.25, rel=1e-9)
    assert 0.05 < float(zwd) < 0.12
    corr = pytest.importorskip("gnsstoolbox.gnss_corr")
    theirs = corr.corr_dtropo_saast(1013.25, 288.16, 50.0, 0.0, 0.0)
    assert float(zhd + zwd) == pytest.approx(float(theirs), abs=0.01)
    assert float(atm.tropo_mapping(np.radians(90.0))) == pytest.approx(1.0, abs=1e-3)
    assert 9.0 < float(atm.tropo_mapping(np.radians(5.0))) < 11.0
