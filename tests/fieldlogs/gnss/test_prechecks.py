"""The paper's pre-checks, sky masks, the corrections seam and carrier smoothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fieldlogs.gnss import skymask
from fieldlogs.gnss.constants import WEEK_S
from fieldlogs.gnss.corrections import match_corrections
from fieldlogs.gnss.observables import FLAG_NAV_MISMATCH, FLAG_PR_DIFFERENCE, build_epochs, carrier_smoothed
from fieldlogs.gnss.prechecks import (
    check_receiver_pair,
    compare_navigation,
    flag_nav_mismatch,
    pseudorange_difference_check,
)
from fieldlogs.simulate.gnss.constellation import constellation_nav
from schemas.errors import InputError

T0 = 2300 * WEEK_S + 3600.0


def test_navigation_comparison_drops_the_disagreeing_satellite() -> None:
    nav = constellation_nav(T0, T0 + 600.0, seed=2, systems=("G",))
    other = nav.copy()
    hit = (other["sat"] == "G07") & (other["Toe"] == other.loc[other["sat"] == "G07", "Toe"].iloc[1])
    other.loc[hit, "M0"] += 1e-6  # one bit error in one receiver's record
    mismatch = compare_navigation({"rx1": nav, "rx2": other})
    assert list(mismatch.table["sat"]) == ["G07"]
    assert mismatch.table["field"].iloc[0] == "M0"
    obs = pd.DataFrame(
        {"t": T0, "gnss_time_s": T0, "receiver": "rx1", "sat": ["G07", "G08"], "signal": "C1C", "pseudorange_m": 2.2e7}
    )
    ep = build_epochs(obs, nav)
    flag_nav_mismatch(ep, mismatch)
    assert (ep.flags[0][ep.sat[0] == "G07"] & FLAG_NAV_MISMATCH).all()
    assert not (ep.flags[0][ep.sat[0] == "G08"] & FLAG_NAV_MISMATCH).any()
    assert compare_navigation({"rx1": nav, "rx2": nav.copy()}).table.empty


def test_pseudorange_difference_check() -> None:
    """Antennas 16 m apart: differences are the clock difference ± up to 16 m; an outlier beyond
    2·(D + tol) = 36 m from every other satellite's interval always fails."""
    rng = np.random.default_rng(1)
    clock_diff = 1234.0
    geo = rng.uniform(-16.0, 16.0, (5, 6))
    pr_b = rng.uniform(2.0e7, 2.5e7, (5, 6))
    pr_a = pr_b + clock_diff + geo
    pr_a[2, 4] += 70.0
    fail = pseudorange_difference_check(pr_a, pr_b, np.ones((5, 6), bool), 16.0, 2.0)
    expect = np.zeros((5, 6), bool)
    expect[2, 4] = True
    np.testing.assert_array_equal(fail, expect)
    one = np.zeros((5, 6), bool)
    one[:, 0] = True
    assert not pseudorange_difference_check(pr_a, pr_b, one, 16.0, 2.0).any()  # one common satellite: no check


def test_receiver_pair_flags_both_receivers() -> None:
    nav = constellation_nav(T0, T0 + 600.0, seed=2, systems=("G",))
    sats = ["G01", "G02", "G03", "G04"]
    pr = np.array([2.1e7, 2.2e7, 2.3e7, 2.4e7])
    obs = pd.concat(
        [
            pd.DataFrame(
                {
                    "t": T0,
                    "gnss_time_s": T0,
                    "receiver": "rx1",
                    "sat": sats,
                    "signal": "C1C",
                    "pseudorange_m": pr + np.array([0.0, 3.0, -2.0, 60.0]),
                }
            ),
            pd.DataFrame(
                {
                    "t": T0,
                    "gnss_time_s": T0 + 1e-4,
                    "receiver": "rx2",
                    "sat": sats[::-1],
                    "signal": "C1C",
                    "pseudorange_m": pr[::-1],
                }
            ),
        ]
    )
    ep = build_epochs(obs, nav)
    ep.flags[:] = 0
    assert check_receiver_pair(ep, "rx1", "rx2", 16.0, 4.0) == 1
    for e in range(2):
        bad = ep.sat[e][(ep.flags[e] & FLAG_PR_DIFFERENCE) > 0]
        assert list(bad) == ["G04"]


def test_sky_masks(tmp_path: Path) -> None:
    az = np.radians([10.0, 170.0, 190.0, 350.0])
    el = np.radians([30.0, 30.0, 85.0, 5.0])
    np.testing.assert_array_equal(skymask.west_half().blocked(az, el), [False, False, True, True])
    np.testing.assert_array_equal(skymask.east_half().blocked(az, el), [True, True, False, False])
    assert not skymask.load_mask("none").blocked(az, el).any()
    f = tmp_path / "mask.csv"
    f.write_text("azimuth_deg,elevation_deg\n0,10\n90,40\n180,90\n270,0\n")
    m = skymask.load_mask(f)
    np.testing.assert_array_equal(
        m.blocked(np.radians([45, 100, 200, 300]), np.radians([20, 20, 89, 1])), [False, True, True, False]
    )
    f.write_text("azimuth_deg,elevation_deg\n0,10\n90,95\n")
    with pytest.raises(InputError, match=r"mask.csv:3, column 'elevation_deg'"):
        skymask.load_mask(f)
    with pytest.raises(InputError, match="cannot read"):
        skymask.load_mask(tmp_path / "missing.csv")


def test_corrections_latest_within_age_and_do_not_use() -> None:
    corr = pd.DataFrame(
        {
            "gnss_time_s": [100.0, 106.0, 100.0],
            "sat": ["G01", "G01", "G02"],
            "prc_m": [1.0, 2.0, -3.0],
            "rrc_mps": [0.0, 0.5, 0.0],
            "usable": [True, True, False],
        }
    )
    m = match_corrections(
        corr, np.array(["G01", "G01", "G02", "G01", "G03"]), np.array([105.0, 108.0, 101.0, 200.0, 105.0])
    )
    np.testing.assert_allclose(m.prc_m, [1.0, 3.0, -3.0, 0.0, 0.0])
    np.testing.assert_array_equal(m.present, [True, True, True, False, False])
    np.testing.assert_array_equal(m.usable, [True, True, False, True, True])


def test_carrier_smoothing_averages_code_noise_and_restarts() -> None:
    rng = np.random.default_rng(3)
    n = 200
    t = np.arange(n, dtype=float)
    lam = 299_792_458.0 / 1575.42e6
    rng_true = 2.2e7 + 500.0 * t
    obs = pd.DataFrame(
        {
            "t": t, "gnss_time_s": t, "receiver": "rx1", "sat": "G01", "signal": "C1C",
            "pseudorange_m": rng_true + rng.normal(0.0, 1.0, n),
            "carrier_cycles": rng_true / lam + 1e5, "lli": 0,
        }
    )  # fmt: skip
    obs.loc[120, "lli"] = 1
    sm = carrier_smoothed(obs, window_s=50.0)
    err = sm["pseudorange_m"].to_numpy() - rng_true
    assert np.std(err[60:120]) < 0.25
    assert sm["smooth_n"].iloc[119] == 50 and sm["smooth_n"].iloc[120] == 1 and sm["smooth_n"].iloc[130] == 11
    assert obs["pseudorange_m"].iloc[0] != sm["pseudorange_m"].iloc[5]  # input not modified, output smoothed


def test_corrections_enter_the_corrected_pseudorange() -> None:
    """PRC adds to the range, the long-term terms move the satellite and its clock, and a D-GPS
    correction that covers the atmosphere switches the models off."""
    from fieldlogs.gnss.geodesy import geodetic_to_ecef
    from fieldlogs.gnss.observables import apply_geometry

    nav = constellation_nav(T0, T0 + 600.0, seed=2, systems=("G",))
    obs = pd.DataFrame(
        {"t": T0, "gnss_time_s": T0, "receiver": "rx1", "sat": ["G01", "G02"], "signal": "C1C", "pseudorange_m": 2.2e7}
    )
    corr = pd.DataFrame(
        {
            "gnss_time_s": [T0 - 1.0, T0 - 1.0], "sat": ["G01", "G02"], "prc_m": [5.0, -2.0],
            "dx_m": [1.0, 0.0], "dclock_s": [1e-9, 0.0], "covers_atmosphere": [True, False],
        }
    )  # fmt: skip
    raw = build_epochs(obs, nav)
    ep = build_epochs(obs, nav, corrections=corr)
    np.testing.assert_allclose(ep.sat_pos[0, :, 0] - raw.sat_pos[0, :, 0], [1.0, 0.0])
    np.testing.assert_allclose(ep.clock_m[0] - raw.clock_m[0], [0.299792458, 0.0])
    rx = geodetic_to_ecef(np.radians(35.7), np.radians(139.7), 40.0)[None]
    iono = {"gps_alpha": (1e-8, 0.0, 0.0, 0.0), "gps_beta": (9e4, 0.0, 0.0, 0.0)}
    g_raw, g = apply_geometry(raw, rx, iono_params=iono), apply_geometry(ep, rx, iono_params=iono)
    assert g.iono_m[0, 0] == 0.0 and g.tropo_m[0, 0] == 0.0 and g.iono_m[0, 1] > 0.0
    np.testing.assert_allclose(g.pr_corr_m[0, 1] - g_raw.pr_corr_m[0, 1], -2.0)
