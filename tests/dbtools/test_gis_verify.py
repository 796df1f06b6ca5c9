"""GIS verification (issue 6): statistics on hand-made offsets, geometry signs, and a small
simulated end-to-end case against truth (``gis_verify_data``)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from dbtools.database import read_network
from dbtools.gis.matching import track_index_for
from dbtools.gis.verify.cells import adjust_pvalues, t_test
from dbtools.gis.verify.config import (
    CELL_COLUMNS,
    COVERAGE_COLUMNS,
    DEFECT,
    DEFECT_COLUMNS,
    FIX_COLUMNS,
    UNVERIFIED,
    VERIFIED,
    VerifyConfig,
)
from dbtools.gis.verify.defects import merge_defects
from dbtools.gis.verify.proposal import proposed_network, shift_grid_points
from dbtools.gis.verify.run import verify_fixes
from dbtools.network import Network
from fieldlogs.gisverify.evidence import collect_evidence
from fieldlogs.simulate.networks.alignment import Alignment
from fieldlogs.simulate.networks.synthetic import LineSpec, build_network
from schemas.errors import InputError
from tests.dbtools.gis_verify_data import (
    DEFECT_KM,
    DEFECT_SHIFT_M,
    DEFECT_TRACK,
    LINE,
    PROJECTOR,
    VerifyData,
    verify_data,
)

TRACK_Y = {"D": 1.9, "U": -1.9}  # straight line running east: D lies north (left of increasing km)


@pytest.fixture(scope="module")
def straight() -> Network:
    """A 2 km straight double-track line running east from the zone 9 origin, km 0–2000."""
    spec = LineSpec("0100", "straight", Alignment(2000.0, [], x0=0.0, y0=0.0, heading0=0.0, km0=0.0))
    return build_network([spec], PROJECTOR)


def fixes(rows: list[tuple[str, str, float, float]]) -> pd.DataFrame:
    """(run, track, km, offset) → fix rows: positions in the plane, offset + = north."""
    run, track, km, off = (list(c) for c in zip(*rows, strict=True))
    y = np.array([TRACK_Y[t] for t in track]) + np.array(off)
    lon, lat = PROJECTOR.to_lonlat(np.array(km, dtype=float), y)
    return pd.DataFrame(
        {"run_id": run, "t": 0.0, "lat": lat, "lon": lon, "line_code": "0100", "track": track, "km_ref_m": np.nan}
    )[list(FIX_COLUMNS)]


def runs_over(
    track: str, n_runs: int, points: dict[float, float], rng: np.random.Generator, *, per_cell: int = 1
) -> list[tuple[str, str, float, float]]:
    """Each run: ``per_cell`` fixes per 20 m cell at random km over km 0–2000; offset = the
    run's own slow GPS error (σ 0.7 m) + 0.1 m noise + the GIS error at that km, linear
    between the grid points given in ``points`` (km → lateral error of that point [m])."""
    pk = np.arange(0.0, 2001.0, 20.0)
    ps = np.array([points.get(float(k), 0.0) for k in pk])
    rows = []
    for r in range(n_runs):
        bias = rng.normal(0.0, 0.7)
        kms = np.sort(rng.uniform(0.0, 2000.0, 100 * per_cell))
        err = np.interp(kms, pk, ps)
        rows += [(f"{track}{r}", track, float(k), bias + rng.normal(0, 0.1) + e) for k, e in zip(kms, err, strict=True)]
    return rows


# ------------------------------------------------------------------------------ pure statistics


def test_t_test_matches_scipy() -> None:
    x = np.array([1.2, 0.4, 2.0, 1.1, 0.9])
    t, p = t_test([x.mean()], [x.std(ddof=1)], [x.size])
    ref = stats.ttest_1samp(x, 0.0)
    assert t[0] == pytest.approx(ref.statistic)
    assert p[0] == pytest.approx(ref.pvalue)
    _, p_few = t_test([1.0], [0.5], [1])
    assert np.isnan(p_few[0])


def test_adjust_pvalues_bh_and_bonferroni_by_hand() -> None:
    p = np.array([0.01, 0.04, 0.03, np.nan, 0.5])
    # BH, m = 4: sorted 0.01, 0.03, 0.04, 0.5 → 0.04, 0.04·… : q = min_{j≥i} p_(j)·4/j
    np.testing.assert_allclose(adjust_pvalues(p), [0.04, 0.04 * 4 / 3, 0.04 * 4 / 3, np.nan, 0.5])
    np.testing.assert_allclose(adjust_pvalues(p, "bonferroni"), [0.04, 0.16, 0.12, np.nan, 1.0])


def test_merge_neighbours_gap_sign_and_track() -> None:
    idx = [10, 11, 12, 14, 15, 19, 20, 21, 30]
    status = [DEFECT] * 9
    mean = [1, 1, 1, 1, 1, 1, 1, -1, 1]
    tid = np.zeros(40, dtype=np.int64)
    tid[30:] = 1
    cells = pd.DataFrame({"status": status, "offset_mean_m": mean}, index=idx)
    lab = merge_defects(cells, tid, max_gap_cells=1)
    # 10–12 + 14–15 (one cell gap), 19–20 (three cells from 15), 21 (sign), 30 (other track)
    assert lab.to_list() == [0, 0, 0, 0, 0, 1, 1, 2, 3]
    assert merge_defects(cells, tid, max_gap_cells=0).to_list() == [0, 0, 0, 1, 1, 2, 2, 3, 4]
    holes = np.ones(40, dtype=bool)
    holes[13] = False  # a km break: no cell 13, never merge across it
    assert merge_defects(cells, tid, 1, holes).to_list() == [0, 0, 0, 1, 1, 2, 2, 3, 4]


# ------------------------------------------------------------------------------ geometry signs


def test_shift_grid_points_moves_left_perpendicular(straight: Network) -> None:
    g = straight.gis
    moved = shift_grid_points(g, "0100", "D", [100.0, 120.0], [1.0, -0.5], PROJECTOR)
    x0, y0 = PROJECTOR.to_xy(g["lon"].to_numpy(), g["lat"].to_numpy())
    x1, y1 = PROJECTOR.to_xy(moved["lon"].to_numpy(), moved["lat"].to_numpy())
    d = (g["track"] == "D") & g["km_m"].isin([100.0, 120.0])
    np.testing.assert_allclose(
        y1[d.to_numpy()] - y0[d.to_numpy()], [1.0, -0.5], atol=2e-4
    )  # east-running: left = north
    np.testing.assert_allclose(x1 - x0, 0.0, atol=2e-4)
    assert (np.abs(y1 - y0)[~d.to_numpy()] < 1e-6).all()
    with pytest.raises(ValueError, match="not on the grid"):
        shift_grid_points(g, "0100", "D", [105.0], 1.0, PROJECTOR)


def test_offset_sign_and_cells(straight: Network) -> None:
    f = fixes([("r1", "D", 30.0, 0.8), ("r1", "U", 30.0, -0.4), ("r1", "D", 1999.9, 0.0), ("r1", "D", 30.0, 12.0)])
    res = verify_fixes(straight, f, VerifyConfig(max_offset_m=10.0))
    c = res.cells.set_index(["track", "km_from_m"])
    assert c.loc[("D", 20.0), "offset_mean_m"] == pytest.approx(0.8, abs=1e-3)  # north of D = left = +
    assert c.loc[("U", 20.0), "offset_mean_m"] == pytest.approx(-0.4, abs=1e-3)
    assert c.loc[("D", 1980.0), "km_to_m"] == 2000.0
    assert res.counts["fixes_far"] == 1  # 12 m off: not evidence


# ------------------------------------------------------------------------------ hand-made evidence


def test_significant_cells_become_one_defect_others_verified(straight: Network) -> None:
    rng = np.random.default_rng(3)
    shift = dict.fromkeys(np.arange(800.0, 1001.0, 20.0), 2.0)
    small = dict.fromkeys(np.arange(1400.0, 1601.0, 20.0), 0.3)  # real but below min shift
    rows = runs_over("D", 12, shift | small, rng, per_cell=2)
    res = verify_fixes(straight, fixes(rows))
    assert list(res.cells.columns) == list(CELL_COLUMNS)
    assert list(res.defects.columns) == list(DEFECT_COLUMNS)
    d = res.defects
    assert len(d) == 1
    # the cells either side see half the error on average: flagged or not, ±20 m
    assert abs(d.loc[0, "km_from_m"] - 800.0) <= 20 and abs(d.loc[0, "km_to_m"] - 1000.0) <= 20
    assert d.loc[0, "shift_m"] == pytest.approx(2.0, abs=0.5)
    assert d.loc[0, "runs"] == 12 and d.loc[0, "p_value"] < 1e-4
    cells = res.cells[res.cells["track"] == "D"]
    away = ~cells["km_from_m"].between(780.0, 1000.0)  # the defect and its half-shifted neighbours
    assert (cells.loc[away, "status"] == VERIFIED).all()
    assert (cells.loc[cells["km_from_m"].between(1400.0, 1580.0), "reason"] == "").all()  # 0.3 m: not worth it
    # the proposal moves exactly the stretch's 11 points (800 … 1000), by about 2 m
    p = res.proposal
    assert p["km_m"].tolist() == list(np.arange(800.0, 1001.0, 20.0))
    np.testing.assert_allclose(p["shift_m"], 2.0, atol=0.5)


def test_proposal_removes_the_offset(straight: Network) -> None:
    rng = np.random.default_rng(4)
    shift = dict.fromkeys(np.arange(1000.0, 1201.0, 20.0), -2.5)
    rows = runs_over("D", 10, shift, rng, per_cell=4)
    f = fixes(rows)
    res = verify_fixes(straight, f)
    assert len(res.defects) == 1
    fixed = proposed_network(straight, res)
    again = verify_fixes(fixed, f)
    assert again.defects.empty
    c = again.cells[(again.cells["track"] == "D") & again.cells["km_from_m"].between(980, 1200)]
    assert c["offset_mean_m"].abs().max() < 0.5
    unchanged = fixed.gis.merge(straight.gis, on=["line_code", "track", "km_m"])
    other = ~((unchanged["track"] == "D") & unchanged["km_m"].between(980, 1220))
    assert (unchanged.loc[other, "lat_x"] == unchanged.loc[other, "lat_y"]).all()


def test_little_evidence_is_unverified_never_good(straight: Network) -> None:
    rng = np.random.default_rng(5)
    rows = runs_over("U", 2, {}, rng)  # two runs: too few
    rows += [(f"x{r}", "D", 510.0, float(rng.normal(0, 0.1))) for r in range(3)]  # 3 runs but 3 fixes
    res = verify_fixes(straight, fixes(rows))
    u = res.cells[res.cells["track"] == "U"]
    assert (u["status"] == UNVERIFIED).all() and (u["reason"] == "fewer than 3 runs").all()
    d = res.cells[res.cells["track"] == "D"].iloc[0]
    assert d["status"] == UNVERIFIED and d["reason"] == "fewer than 5 fixes"
    cov = res.coverage.set_index("track")
    assert list(res.coverage.columns) == list(COVERAGE_COLUMNS)
    assert cov.loc["U", "verified_km"] == 0 and cov.loc["U", "unverified_km"] == pytest.approx(2.0)
    assert cov.loc["D", "unverified_share"] == pytest.approx(1.0)  # untraversed cells count as unverified
    assert res.defects.empty


def test_noisy_cell_is_inconclusive(straight: Network) -> None:
    rng = np.random.default_rng(6)
    rows = runs_over("D", 4, {}, rng, per_cell=4)
    rows = [(r, t, k, o * (6.0 if k < 200 else 1.0)) for r, t, k, o in rows]  # ±4 m between runs
    res = verify_fixes(straight, fixes(rows))
    first = res.cells[(res.cells["track"] == "D") & (res.cells["km_from_m"] < 200)]
    assert (first["status"] == UNVERIFIED).all()
    enough = (first["runs"] >= 3) & (first["fixes"] >= 5)
    assert enough.sum() >= 5 and first.loc[enough, "reason"].str.contains("95 % CI").all()


def test_json_shape(straight: Network) -> None:
    rng = np.random.default_rng(7)
    res = verify_fixes(straight, fixes(runs_over("D", 5, {900.0: 3.0, 920.0: 3.0}, rng, per_cell=2)))
    data = json.loads(json.dumps(res.to_dict()))
    assert set(data) == {
        "config",
        "counts",
        "km_residual",
        "coverage",
        "defects",
        "proposal",
        "km_defects",
        "scan",
        "cells",
    }
    assert set(data["cells"][0]) == set(CELL_COLUMNS)
    assert data["config"]["alpha"] == 0.01


def test_empty_evidence_and_empty_grid(straight: Network) -> None:
    res = verify_fixes(straight, pd.DataFrame(columns=list(FIX_COLUMNS)))
    assert res.cells.empty and res.defects.empty and res.proposal.empty
    assert (res.coverage["unverified_share"] == 1.0).all()
    no_grid = Network({**straight.tables, "gis": straight.gis.iloc[:0]}, origin="empty.sqlite")
    with pytest.raises(InputError, match="no GIS grid"):
        verify_fixes(no_grid, fixes([("r", "D", 10.0, 0.0)]))


# ------------------------------------------------------------------------------ simulated truth


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> VerifyData:
    return verify_data(tmp_path_factory)


def test_simulated_defect_found_located_and_corrected(data: VerifyData) -> None:
    surveyed = read_network(data.surveyed_db)
    truth = read_network(data.truth_db)
    ev = collect_evidence(data.runs, data.surveyed_db, network=surveyed)
    assert ev.totals()["used"] > 0.8 * ev.totals()["gps_fixes"] * 0.8
    res = verify_fixes(surveyed, ev.fixes)
    assert len(res.defects) == 1, res.defects
    d = res.defects.iloc[0]
    assert (d["line_code"], d["track"]) == (LINE, DEFECT_TRACK)
    assert abs(d["km_from_m"] - DEFECT_KM[0]) <= 40 and abs(d["km_to_m"] - DEFECT_KM[1]) <= 40
    # fixes sit right of the surveyed (left-shifted) grid: negative offset, moved back right
    assert d["shift_m"] == pytest.approx(-DEFECT_SHIFT_M, abs=0.5)
    fixed = proposed_network(surveyed, res)
    idx = track_index_for(truth)
    key = ["line_code", "track", "km_m"]
    m = truth.gis.merge(fixed.gis, on=key, suffixes=("_t", "_p"))
    xt, yt = idx.projector.to_xy(m["lon_t"].to_numpy(), m["lat_t"].to_numpy())
    xp, yp = idx.projector.to_xy(m["lon_p"].to_numpy(), m["lat_p"].to_numpy())
    err = np.hypot(xp - xt, yp - yt)
    assert err.max() <= 0.5, m.loc[err > 0.5, key]  # every point of the DB within 0.5 m of the truth


def test_simulated_correct_grid_has_no_defect(data: VerifyData) -> None:
    truth = read_network(data.truth_db)
    ev = collect_evidence(data.runs, data.truth_db, network=truth)
    res = verify_fixes(truth, ev.fixes)
    assert res.defects.empty, res.defects
    cov = res.coverage
    assert (cov["verified_share"] > 0.4).all()  # 8 runs per track verify much of the line
    assert res.km_residual["n"] > 0 and abs(res.km_residual["median_m"]) < 1.0
