"""The GIS-verify scan (issue 19): contrasts and the moderated t by hand, the multiple-testing
correction over windows by hand, and recall / false defects on seeded hand-made fleets of
5 runs per track (1 Hz fixes, Gauss–Markov GPS error σ 0.75 m, τ 180 s)."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import special, stats

from dbtools.gis.geometry import Projector
from dbtools.gis.index import grid_index
from dbtools.gis.verify.cells import Cells
from dbtools.gis.verify.config import DEFECT, FIX_COLUMNS, VerifyConfig
from dbtools.gis.verify.run import verify_fixes
from dbtools.gis.verify.scan import (
    Prior,
    contrasts,
    fit_prior,
    moderated_t,
    select_windows,
    trigamma_inverse,
    window_tests,
)
from dbtools.network import Network
from fieldlogs.simulate.networks.alignment import Alignment
from fieldlogs.simulate.networks.synthetic import LineSpec, build_network
from schemas.errors import InputError

PROJECTOR = Projector(9)
LENGTH_M = 10_000.0
TRACK_Y = {"D": 1.9, "U": -1.9}  # a straight line running east: D lies north (left of increasing km)


@pytest.fixture(scope="module")
def line() -> Network:
    spec = LineSpec("0100", "straight", Alignment(LENGTH_M, [], x0=0.0, y0=0.0, heading0=0.0, km0=0.0))
    return build_network([spec], PROJECTOR)


def gauss_markov(rng: np.random.Generator, n: int, sigma: float = 0.75, tau_s: float = 180.0) -> np.ndarray:
    phi = np.exp(-1.0 / tau_s)
    w = rng.standard_normal(n) * sigma * np.sqrt(1.0 - phi * phi)
    x = np.empty(n)
    x[0] = rng.standard_normal() * sigma
    for i in range(1, n):
        x[i] = phi * x[i - 1] + w[i]
    return x


def fleet(rng: np.random.Generator, runs: int, stretches: list[tuple[str, float, float, float]]) -> pd.DataFrame:
    """``runs`` runs per track at 25 m/s, one fix a second from a random start; lateral
    offset = the run's slow GPS error + the GIS error (points km_from..km_to shifted by
    shift, linear to the neighbouring points, as the DB interpolates)."""
    pk = np.arange(0.0, LENGTH_M + 1.0, 20.0)
    frames = []
    for track in ("D", "U"):
        ps = np.zeros(pk.size)
        for tr, a, b, shift in stretches:
            if tr == track:
                ps[(pk >= a) & (pk <= b)] = shift
        for r in range(runs):
            km = (np.arange(int(LENGTH_M / 25.0)) + rng.uniform(0.0, 1.0)) * 25.0
            km = km[km < LENGTH_M - 1.0]
            off = gauss_markov(rng, km.size) + np.interp(km, pk, ps)
            lon, lat = PROJECTOR.to_lonlat(km, TRACK_Y[track] + off)
            frames.append(
                pd.DataFrame(
                    {
                        "run_id": f"{track}{r}",
                        "t": np.arange(km.size, dtype=float),
                        "lat": lat,
                        "lon": lon,
                        "line_code": "0100",
                        "track": track,
                        "km_ref_m": np.nan,
                    }
                )
            )
    return pd.concat(frames, ignore_index=True)[list(FIX_COLUMNS)]


# ------------------------------------------------------------------------------ by hand


def test_trigamma_inverse_and_prior_by_hand() -> None:
    for y in (0.3, 1.0, 4.0, 50.0):
        assert trigamma_inverse(float(special.polygamma(1, y))) == pytest.approx(y, rel=1e-6)
    # equal variances vary less than sampling explains: infinite prior df; s0² is the
    # bias-corrected geometric mean, exp(E log s² − ψ(d/2) + log(d/2))
    p = fit_prior(np.full(10, 0.04), np.full(10, 4.0))
    assert p.d0 >= 1e6 and p.windows == 10
    assert p.s0_sq == pytest.approx(0.04 * 2.0 / np.exp(special.digamma(2.0)))
    # variances drawn from the scaled inverse-χ² model itself: d0 and s0² recovered
    rng = np.random.default_rng(1)
    sigma2 = 0.09 * 20.0 / rng.chisquare(20.0, 4000)
    s2 = sigma2 * rng.chisquare(4.0, 4000) / 4.0
    fit = fit_prior(s2, np.full(4000, 4.0))
    assert fit.d0 == pytest.approx(20.0, rel=0.3) and fit.s0_sq == pytest.approx(0.09, rel=0.1)
    assert fit_prior(np.array([0.1, 0.2]), np.array([4.0, 4.0])).d0 == 0.0  # too few: no prior


def test_moderated_t_by_hand() -> None:
    prior = Prior(s0_sq=0.04, d0=10.0, windows=50)
    mean, var, k, w = np.array([0.6, 0.6]), np.array([0.01, 0.25]), np.array([5.0, 5.0]), np.array([2.0, 2.0])
    se, df, t, p = moderated_t(mean, var, k, w, prior)
    s2 = (10 * 0.04 + 4 * 0.01) / 14  # moderated: pulled up towards the prior
    assert se[0] == pytest.approx(np.sqrt(s2 / 2.0)) and df[0] == 14.0
    assert t[0] == pytest.approx(0.6 / np.sqrt(s2 / 2.0))
    assert p[0] == pytest.approx(2 * stats.t.sf(abs(t[0]), 14))
    assert se[1] == pytest.approx(np.sqrt(0.25 / 2.0))  # an own spread above the moderated one stands


def test_contrast_by_hand() -> None:
    """Two runs on a 12-cell track, windows of 2 cells, flanks of 2 cells one cell away:
    contrast = mean(core) − ½(mean(left) + mean(right)), weight 1/h with h from the times."""
    net = build_network([LineSpec("0100", "s", Alignment(260.0, [], x0=0.0, y0=0.0, heading0=0.0, km0=0.0))], PROJECTOR)
    grid = Cells.build(grid_index(net))
    d_cells = np.flatnonzero(grid.tid == grid.tid[0])[:12]
    v = np.array([0, 0, 0, 0, 0, 2, 2, 0, 0, 0, 0, 0], dtype=float)
    rows = []
    for run, bias in ((0, 0.5), (1, -0.3)):
        for i, c in enumerate(d_cells):
            rows.append({"cell": int(c), "unit": run, "v": v[i] + bias, "t": 10.0 * i})
    win = contrasts(pd.DataFrame(rows), grid, [2], gap=1, flank=2)
    w5 = win[win["first"] == d_cells[5]].iloc[0]
    # core cells 5–6 = 2 + bias, flanks 2–3 and 8–9 = bias: contrast 2 for both runs
    assert w5["units"] == 2 and w5["mean_m"] == pytest.approx(2.0) and w5["var_m2"] == pytest.approx(0.0)
    # h = ¼(|55 − 25| + |85 − 55|) = 15 s per run
    assert w5["weight"] == pytest.approx(2 / 15.0)
    w0 = win[win["first"] == d_cells[0]].iloc[0]  # at the track start only the right flank (3–4)
    assert w0["mean_m"] == pytest.approx(0.0) and w0["weight"] == pytest.approx(2 / 30.0)


def test_bonferroni_and_bh_over_windows_by_hand() -> None:
    """Four windows, one prior per length: q = min(1, 4·p) (Bonferroni), BH step-up."""
    windows = pd.DataFrame(
        {
            "tid": 0,
            "first": [0, 5, 10, 15],
            "cells": 5,
            "units": 5.0,
            "weight": 1.0,
            "mean_m": [2.0, 0.1, -0.05, 0.6],
            "var_m2": [0.04, 0.05, 0.03, 0.04],
        }
    )
    tested, priors = window_tests(windows, min_units=3, correction="bonferroni")
    prior = priors[5]
    assert prior.windows == 4
    _, _, _, p = moderated_t(
        windows["mean_m"].to_numpy(), windows["var_m2"].to_numpy(), np.full(4, 5.0), np.ones(4), prior
    )
    np.testing.assert_allclose(tested["p_value"], p)
    np.testing.assert_allclose(tested["q_value"], np.minimum(1.0, 4 * p))
    bh, _ = window_tests(windows, min_units=3, correction="bh")
    order = np.argsort(p)
    ranked = np.minimum.accumulate((p[order] * 4 / np.arange(1, 5))[::-1])[::-1]
    expect = np.empty(4)
    expect[order] = ranked
    np.testing.assert_allclose(bh["q_value"], np.minimum(expect, 1.0))
    few, _ = window_tests(windows.assign(units=2.0), min_units=3, correction="bonferroni")
    assert few.empty  # fewer units than min_runs: not tested, not counted


def test_selection_takes_the_fitting_window_and_drops_its_neighbours() -> None:
    tested = pd.DataFrame(
        {
            "tid": 0,
            "first": [100, 102, 95, 115, 300],
            "cells": [10, 5, 20, 5, 5],
            "units": 5.0,
            "mean_m": [2.0, 1.6, 1.0, -0.9, 0.3],  # 115: a neighbour with the stretch in its flank
            "t_stat": [30.0, 35.0, 20.0, -12.0, 9.0],
            "p_value": 1e-12,
            "q_value": 1e-9,
        }
    )
    sel = select_windows(tested, alpha=0.01, min_shift_m=0.5, reach=11)
    assert sel["first"].tolist() == [100] and sel["last"].tolist() == [109]  # 300: below min shift


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=8),
    st.floats(-1.0, 1.0),
)
def test_a_common_bias_cancels(offsets: list[float], bias: float) -> None:
    """Adding the same value to every cell of a unit changes no contrast (the slow GPS
    error of a run is removed, whatever it is)."""
    net = build_network([LineSpec("0100", "s", Alignment(400.0, [], 0.0, 0.0, 0.0, km0=0.0))], PROJECTOR)
    grid = Cells.build(grid_index(net))
    cells = np.flatnonzero(grid.tid == grid.tid[0])[: len(offsets) * 2]
    base = pd.DataFrame(
        {"cell": cells, "unit": 0, "v": np.resize(np.array(offsets), cells.size), "t": np.arange(cells.size) * 1.0}
    )
    a = contrasts(base, grid, [1, 2], gap=1, flank=2)
    b = contrasts(base.assign(v=base["v"] + bias), grid, [1, 2], gap=1, flank=2)
    np.testing.assert_allclose(a["mean_m"], b["mean_m"], atol=1e-9)


# ------------------------------------------------------------------------------ seeded fleets


def test_five_runs_find_every_stretch_of_1_5_m_over_100_m(line: Network) -> None:
    found = total = false = 0
    for seed in range(4):
        rng = np.random.default_rng(100 + seed)
        stretches = [
            (tr, a, a + length, float(rng.uniform(1.5, 2.0)) * float(rng.choice([-1.0, 1.0])))
            for tr in ("D", "U")
            for a, length in ((1500.0 + 100 * seed, 100.0), (5000.0, 140.0), (8000.0 - 100 * seed, 300.0))
        ]
        res = verify_fixes(line, fleet(rng, 5, stretches))
        d = res.defects
        used = np.zeros(len(d), dtype=bool)
        for tr, a, b, shift in stretches:
            ov = ((d["track"] == tr) & (d["km_from_m"] < b) & (d["km_to_m"] > a)).to_numpy()
            found += bool(ov.any())
            total += 1
            used |= ov
            if ov.any():
                hit = d[ov].iloc[0]
                assert hit["shift_m"] == pytest.approx(shift, abs=0.5)
                assert abs(hit["km_from_m"] - a) <= 40 and abs(hit["km_to_m"] - b) <= 40
                assert np.isfinite(hit["scan_q"]) and hit["scan_q"] <= 0.01
        false += int((~used).sum())
        # the cells of a pooled defect are defect cells, whatever their own evidence
        assert (res.cells.loc[res.cells["reason"].str.contains("window"), "status"] == DEFECT).all()
    assert found / total >= 0.95 and false == 0


def test_clean_tracks_give_no_defect(line: Network) -> None:
    for seed in range(6):
        res = verify_fixes(line, fleet(np.random.default_rng(200 + seed), 5, []))
        assert res.defects.empty and res.km_defects.empty
        assert res.scan["lateral"]["windows_tested"] > 1000


def test_scan_off_is_the_cell_test_alone(line: Network) -> None:
    rng = np.random.default_rng(7)
    f = fleet(rng, 5, [("D", 3000.0, 3300.0, 2.0)])
    assert len(verify_fixes(line, f).defects) == 1
    off = verify_fixes(line, f, VerifyConfig(scan=False))
    assert off.defects.empty  # one fix per pass per cell, five runs: no single cell is enough
    assert off.scan["lateral"]["windows_tested"] == 0


def test_unverified_cells_stay_unverified_under_the_scan(line: Network) -> None:
    rng = np.random.default_rng(8)
    res = verify_fixes(line, fleet(rng, 5, []), VerifyConfig(min_fixes=6))
    # five runs, one fix each per cell: every cell short of evidence, none called verified
    assert (res.cells["status"] == "unverified").all()
    assert (res.coverage["verified_km"] == 0).all()


def test_config_is_checked() -> None:
    with pytest.raises(InputError, match=re.escape("'gis_verify.scan_correction' = 'max' is not one of")):
        VerifyConfig(scan_correction="max")
    with pytest.raises(InputError, match=re.escape("'gis_verify.scan_windows_m' = (100.0, -20.0) m is out of range")):
        VerifyConfig(scan_windows_m=(100.0, -20.0))
    with pytest.raises(InputError, match=re.escape("'gis_verify.alpha' = 0.7 is out of range")):
        VerifyConfig(alpha=0.7)


def test_along_track_residual_stretch_is_found_and_a_drift_is_not(line: Network) -> None:
    """Pipeline km = true km + the run's drift (0.3 % of the travel since its last balise,
    every 1.5 km, the same for every run: one vehicle's wheel error) + 0.3 m noise; on D
    km 4000–4200 the GIS km is 2 m short of the truth (grid points placed 2 m too early)."""
    rng = np.random.default_rng(11)
    f = fleet(rng, 5, [])
    km_true, _ = PROJECTOR.to_xy(f["lon"].to_numpy(), f["lat"].to_numpy())  # the line runs east from x = km = 0
    since = np.mod(km_true, 1500.0)
    gis_err = np.where((f["track"] == "D").to_numpy() & (km_true >= 4000) & (km_true < 4200), 2.0, 0.0)
    f["km_ref_m"] = km_true + 0.003 * since + rng.normal(0.0, 0.3, len(f)) + gis_err
    f["km_ref_epoch"] = (km_true // 1500.0).astype(int)
    res = verify_fixes(line, f)
    k = res.km_defects
    assert len(k) == 1, k
    row = k.iloc[0]
    assert row["track"] == "D" and abs(row["km_from_m"] - 4000) <= 40 and abs(row["km_to_m"] - 4200) <= 40
    assert row["residual_m"] == pytest.approx(-2.0, abs=0.4)  # GIS km − pipeline km
    assert res.has_defects and res.defects.empty
    clean = verify_fixes(line, f.assign(km_ref_m=f["km_ref_m"] - gis_err))
    assert clean.km_defects.empty  # the drift alone is no defect


def test_blocks_of_units_give_the_same_windows(line: Network, monkeypatch: pytest.MonkeyPatch) -> None:
    """Units summed in blocks (bounded memory) give the windows of one block."""
    import importlib

    scan_mod = importlib.import_module("dbtools.gis.verify.scan")  # the package exports a function `scan`
    rng = np.random.default_rng(12)
    f = fleet(rng, 4, [("U", 2000.0, 2200.0, 2.0)])
    one = verify_fixes(line, f)
    monkeypatch.setattr(scan_mod, "BLOCK_ENTRIES", 1)  # one unit per block
    many = verify_fixes(line, f)
    assert one.scan == many.scan
    pd.testing.assert_frame_equal(one.defects, many.defects)
