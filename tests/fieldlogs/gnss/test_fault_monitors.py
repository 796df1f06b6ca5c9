"""The slow-ramp fault monitor [S002 integrity]: the code-carrier divergence of the smoothed
arcs, by hand and on seeded ramp runs."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fieldlogs.experiments.gnss import CaseSpec, run_case, summarise
from fieldlogs.gnss.constants import WEEK_S
from fieldlogs.gnss.observables import FLAG_CODE_CARRIER, build_epochs, carrier_smoothed
from fieldlogs.simulate.gnss.constellation import constellation_nav

LAM = 299_792_458.0 / 1575.42e6
T0 = 2300 * WEEK_S + 7200.0


def _arc(n: int, code_extra: np.ndarray) -> pd.DataFrame:
    t = np.arange(n, dtype=float)
    rng_true = 2.2e7 + 500.0 * t
    return pd.DataFrame(
        {
            "t": t, "gnss_time_s": T0 + t, "receiver": "rx1", "sat": "G01", "signal": "C1C",
            "pseudorange_m": rng_true + code_extra, "carrier_cycles": rng_true / LAM + 1e5, "lli": 0,
        }
    )  # fmt: skip


def test_divergence_is_the_code_minus_carrier_slope() -> None:
    """A code-only ramp of 0.2 m/s from sample 50 and a 20 s fit window: NaN for the first 19
    samples, 0 on the flat part, exactly 0.2 m/s once the window lies on the ramp; in between
    the least-squares slope of the kinked line, by hand for the window ending 5 samples after
    the kink: x = 0..19 (the kink between x = 14 and 15), y = 0.2·max(x − 14, 0)."""
    n = 120
    extra = 0.2 * np.clip(np.arange(n) - 50.0, 0.0, None)
    sm = carrier_smoothed(_arc(n, extra), window_s=100.0, divergence_window_s=20.0)
    div = sm["divergence_mps"].to_numpy()
    assert np.isnan(div[:19]).all() and np.isfinite(div[19:]).all()
    np.testing.assert_allclose(div[19:50], 0.0, atol=1e-9)
    np.testing.assert_allclose(div[70:], 0.2, atol=1e-9)
    x = np.arange(20.0)
    y = 0.2 * np.clip(x - 14.0, 0.0, None)
    by_hand = np.sum((x - x.mean()) * (y - y.mean())) / np.sum((x - x.mean()) ** 2)
    assert div[55] == pytest.approx(by_hand, abs=1e-9)
    assert 0.0 < by_hand < 0.2


def test_divergence_restarts_with_the_arc_and_sign() -> None:
    n = 80
    extra = -0.5 * np.arange(n, dtype=float)  # a descending ramp
    obs = _arc(n, extra)
    obs.loc[40, "lli"] = 1  # loss of lock: a new arc, no slope for its first window
    div = carrier_smoothed(obs, divergence_window_s=10.0)["divergence_mps"].to_numpy()
    np.testing.assert_allclose(div[9:40], -0.5, atol=1e-9)
    assert np.isnan(div[40:49]).all()
    np.testing.assert_allclose(div[49:], -0.5, atol=1e-9)


def test_build_epochs_flags_a_divergent_arc_only_beyond_the_limit() -> None:
    nav = constellation_nav(T0, T0 + 600.0, seed=2, systems=("G",))
    n = 150
    obs = _arc(n, 0.2 * np.clip(np.arange(n) - 20.0, 0.0, None))
    sm = carrier_smoothed(obs, divergence_window_s=100.0)
    ep = build_epochs(sm, nav, max_divergence_mps=0.1)
    flagged = (ep.flags[:, 0] & FLAG_CODE_CARRIER) > 0
    div = sm["divergence_mps"].to_numpy()
    np.testing.assert_array_equal(flagged, np.nan_to_num(np.abs(div)) > 0.1)
    assert flagged[-1] and not flagged[:99].any()
    off = build_epochs(sm, nav)  # no limit given: no flag
    assert not ((off.flags & FLAG_CODE_CARRIER) > 0).any()


@pytest.mark.parametrize("seed", [1000, 1003])
def test_a_slow_ramp_is_excluded_before_it_is_detectable(seed: int) -> None:
    """The 0.2 m/s code ramp of the bench on a used satellite: flagged by the divergence
    monitor, never kept from the 2nd detectable epoch on, no error outside U; the clean run
    of the same seed has no divergence flag."""
    res = run_case(CaseSpec(seed, fault="ramp"))
    s = summarise([res])
    assert s["fault_epochs"] > 100
    assert s["fault_not_excluded_after_2_epochs"] == 0.0
    assert s["fault_exceed_fraction"] == 0.0
    assert s["fault_bias_at_exclusion_m"] < 15.0  # the w-test alone first excluded it at ~19 m
    assert res.epochs["n_divergence"].sum() > 0
    clean = run_case(CaseSpec(seed))
    assert clean.epochs["n_divergence"].sum() == 0
