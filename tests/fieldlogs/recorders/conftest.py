"""Shared helpers of the recorder tests: hand-made data files, frames built by hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from schemas.gnss import GNSS_NAV

DATA = Path(__file__).resolve().parents[2] / "data" / "recorders"
#: 2026-12-01T10:00:00 UTC in GPS seconds, by hand: 17 131 days · 86400 s + 10 h + 18 leap seconds.
T0_GPS = 17_131 * 86_400.0 + 36_000.0 + 18.0


@pytest.fixture
def data() -> Path:
    return DATA


def gps_frame(n: int = 5, t0: float = T0_GPS) -> pd.DataFrame:
    k = np.arange(n, dtype=float)
    return pd.DataFrame(
        {
            "gnss_time_s": t0 + k,
            "lat": 35.9 + 1.234567e-5 * k,
            "lon": 139.4 + 2.345678e-5 * k,
            "fix": np.array([1, 2, 2, 0, 1][:n] + [1] * max(0, n - 5)),
            "nsat": np.array([7, 8, 9, 0, 10][:n] + [9] * max(0, n - 5)),
            "hdop": 0.9 + 0.1 * k,
            "height_m": 40.0 + 0.5 * k,
            "speed_mps": 10.0 + k,
            "course_deg": 90.0 + k,
            "sigma_lat_m": 0.5,
            "sigma_lon_m": 0.6,
            "sigma_height_m": 0.9,
        }
    )


def obs_frame(n_epochs: int = 3, receiver: str = "rx1", t0: float = T0_GPS) -> pd.DataFrame:
    rows = []
    for k in range(n_epochs):
        for sat, signals in (
            ("G07", ("C1C", "C5Q")),
            ("G12", ("C1C",)),
            ("E11", ("C1C", "C7Q")),
            ("J02", ("C1C",)),
            ("R05", ("C1C",)),
        ):
            for j, sig in enumerate(signals):
                rows.append(
                    {
                        "gnss_time_s": t0 + k,
                        "receiver": receiver,
                        "sat": sat,
                        "signal": sig,
                        "pseudorange_m": 2.0e7 + 1000.0 * int(sat[1:]) + 123.456 * k + 0.5 * j,
                        "carrier_cycles": 1.05e8 + 640.25 * k + 7.0 * j,
                        "doppler_hz": -1234.5 + 10.0 * k,
                        "cn0_dbhz": 40.0 + int(sat[1:]) % 7,
                        "lli": 1 if k == 0 else 0,
                    }
                )
    f = pd.DataFrame(rows)
    f["lli"] = f["lli"].astype("Int64")
    return f


def nav_row(sat: str = "G07", t0: float = T0_GPS) -> dict[str, float | str]:
    """A broadcast ephemeris on exact LNAV grid values (each field a whole number of LSBs)."""
    r: dict[str, float | str] = dict.fromkeys(GNSS_NAV.column_names, np.nan)
    week = t0 // 604_800
    toe = (t0 // 16 * 16) % 604_800
    pi = np.pi
    r.update(
        sat=sat,
        toc_gps_s=week * 604_800 + toe,
        SVclockBias=12345 * 2.0**-31,
        SVclockDrift=-7 * 2.0**-43,
        SVclockDriftRate=0.0,
        IODE=45.0,
        Crs=-400 * 2.0**-5,
        DeltaN=1234 * 2.0**-43 * pi,
        M0=123456789 * 2.0**-31 * pi,
        Cuc=-1000 * 2.0**-29,
        Eccentricity=85_899_346 * 2.0**-33,
        Cus=2000 * 2.0**-29,
        sqrtA=2_702_051_533 * 2.0**-19,
        Toe=toe,
        Cic=30 * 2.0**-29,
        Omega0=-987654321 * 2.0**-31 * pi,
        Cis=-40 * 2.0**-29,
        Io=654321987 * 2.0**-31 * pi,
        Crc=8000 * 2.0**-5,
        omega=111222333 * 2.0**-31 * pi,
        OmegaDot=-4321 * 2.0**-43 * pi,
        IDOT=55 * 2.0**-43 * pi,
        TGD=-3 * 2.0**-31,
        health=0.0,
        SVacc=2.4,
        TransTime=(t0 // 6 * 6 - 600) % 604_800,
        FitIntvl=4.0,
        IODC=45.0,
        week=float(week),
    )
    return r
