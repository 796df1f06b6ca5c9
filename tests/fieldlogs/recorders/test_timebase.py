"""GPS time, leap seconds and the recorder clock fit, against hand-computed values."""

from __future__ import annotations

from datetime import datetime

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from fieldlogs.recorders.timebase import (
    _LEAP_N,
    _LEAP_UTC_S,
    UNIX_TO_GPS_S,
    calendar_to_utc_s,
    fit_clock,
    gps_to_iso,
    gps_to_utc,
    iso_to_gps,
    leap_seconds_utc,
    unix_to_gps,
    utc_to_gps,
)
from tests.fieldlogs.recorders.conftest import T0_GPS


def test_epoch_and_leap_seconds_by_hand() -> None:
    assert UNIX_TO_GPS_S == 315_964_800.0  # 3657 days from 1970-01-01 to 1980-01-06
    assert iso_to_gps("1980-01-06T00:00:00+00:00") == 0.0
    # 2017-01-01T00:00:00Z: 37·365 + 10 leap days − 5 = 13 510 days after the GPS epoch;
    # GPS − UTC = 18 s from then on, 17 s just before
    assert iso_to_gps("2017-01-01T00:00:00+00:00") == 13_510 * 86_400.0 + 18.0
    assert iso_to_gps("2016-12-31T23:59:59+00:00") == 13_510 * 86_400.0 - 1.0 + 17.0
    assert float(leap_seconds_utc(13_510 * 86_400.0 - 1.0)) == 17.0
    # a Japanese local time with its offset: 2026-12-01T10:00Z
    days = (datetime(2026, 12, 1) - datetime(1980, 1, 6)).days
    assert iso_to_gps("2026-12-01T19:00:00+09:00") == days * 86_400.0 + 36_000.0 + 18.0 == T0_GPS
    assert float(unix_to_gps(1_483_228_800.0)) == 13_510 * 86_400.0 + 18.0
    assert gps_to_iso(13_510 * 86_400.0 + 18.0) == "2017-01-01T00:00:00.000000+00:00"
    # calendar fields on one scale: 1999-09-02 17:51:44 is Thursday of GPS week 1025, 409 904 s
    assert float(calendar_to_utc_s(1999, 9, 2, 17 * 3600 + 51 * 60 + 44.0)) == 1025 * 604_800 + 409_904


@given(st.floats(min_value=0.0, max_value=2.5e9, allow_nan=False))
def test_utc_gps_round_trip(g: float) -> None:
    # away from a leap second itself (where UTC repeats a second), gps → utc → gps is exact
    leaps = _LEAP_UTC_S + _LEAP_N
    assume(np.min(np.abs(leaps - g)) > 2.0)
    assert float(utc_to_gps(gps_to_utc(g))) == pytest.approx(g, abs=1e-6)
    assert float(iso_to_gps(gps_to_iso(g))) == pytest.approx(g, abs=2e-6)


def test_clock_fit_recovers_a_drifting_recorder() -> None:
    rng = np.random.default_rng(1)
    g = 1.48e9 + np.arange(0.0, 3600.0, 1.0)
    tau = (g - g[0] + 12.0) * (1.0 + 0.008)  # runs 0.8 % fast, started 12 s early
    gnss = g + rng.normal(0.0, 1e-3, len(g))
    fit = fit_clock(tau, gnss)
    assert fit.drift == pytest.approx(0.008, abs=1e-7)
    assert np.max(np.abs(fit.apply(tau) - g)) < 5e-3
    assert 0.5e-3 < fit.residual_rms_s < 2e-3


def test_clock_fit_refuses_a_wrong_unit_or_too_few_pairs() -> None:
    with pytest.raises(ValueError, match="wrong time unit"):
        fit_clock(np.arange(10.0) * 1000.0, 1e9 + np.arange(10.0))
    with pytest.raises(ValueError, match="at least 2"):
        fit_clock([1.0, np.nan], [1e9, 1e9 + 1])
