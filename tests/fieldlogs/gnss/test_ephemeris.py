"""Broadcast ephemeris: worked example, the independent library (gnsstoolbox), Kepler, clocks, selection."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.gnss import ephemeris as eph
from fieldlogs.gnss.constants import C_MPS, F_L1_HZ, F_L2_HZ, F_L5_HZ, GALILEO, GPS, NAV_COLUMNS, WEEK_S
from fieldlogs.simulate.gnss.constellation import constellation_nav

# Real GPS PRN 1 broadcast record of 2013-06-01 02:00 GPST (week 1742, Toe 352800), as printed
# in the docstring of gnsstoolbox's orbits.getEphemeris (J. Beilin, ENSG).
G01_2013 = {
    "sat": "G01",
    "SVclockBias": 3.15997749567000e-05,
    "SVclockDrift": 4.32009983342100e-12,
    "SVclockDriftRate": 0.0,
    "IODE": 94.0,
    "Crs": 2.25,
    "DeltaN": 4.63876465173900e-09,
    "M0": 1.81168558621700,
    "Cuc": 2.75671482086200e-07,
    "Eccentricity": 0.00189499533735200,
    "Cus": 1.05910003185300e-05,
    "sqrtA": 5153.70066070600,
    "Toe": 352800.0,
    "Cic": 2.60770320892300e-08,
    "Omega0": -1.46537454108600,
    "Cis": 1.37835741043100e-07,
    "Io": 0.959848465747100,
    "Crc": 173.687500000000,
    "omega": 0.255929757187400,
    "OmegaDot": -8.04104922769100e-09,
    "IDOT": 3.31799535068200e-10,
    "TGD": 8.38190317153900e-09,
    "health": 0.0,
    "SVacc": 2.0,
    "TransTime": 345600.0,
    "FitIntvl": 4.0,
    "week": 1742.0,
    "toc_gps_s": 1742 * WEEK_S + 352800.0,
}

# Galileo E11 record of the same file (gnsstoolbox docstring); BGDe5b copied as printed (0).
E11_2013 = {
    **G01_2013,
    "sat": "E11",
    "SVclockBias": 9.06531931832400e-04,
    "SVclockDrift": 8.25934876047500e-11,
    "IODE": 64.0,
    "Crs": -127.0,
    "DeltaN": 3.22049128924600e-09,
    "M0": 2.45252068075900,
    "Cuc": -5.72949647903400e-06,
    "Eccentricity": 3.02415806800100e-04,
    "Cus": 1.07511878013600e-05,
    "sqrtA": 5440.61737251300,
    "Toe": 345600.0,
    "Cic": 2.42143869400000e-08,
    "Omega0": -2.27501476678800,
    "Cis": 0.0,
    "Io": 0.957955133762200,
    "Crc": 109.468750000000,
    "omega": -0.819738964252500,
    "OmegaDot": -5.59094717110500e-09,
    "IDOT": -1.00004165574900e-11,
    "TGD": np.nan,
    "BGDe5a": -6.51925802230800e-09,
    "BGDe5b": 0.0,
    "DataSrc": 513.0,
    "FitIntvl": np.nan,
    "toc_gps_s": 1742 * WEEK_S + 345600.0,
}


def _table(*rows: dict[str, object]) -> eph.NavTable:
    return eph.nav_table(pd.DataFrame(list(rows)).reindex(columns=list(NAV_COLUMNS)))


def test_worked_example_is_gps_200_position() -> None:
    """szymon2024/gps-labs gps_lab02 (IS-GPS-200N §20.3.3.4.3): week 2304, tow 424830 → X, Y, Z."""
    row = {
        **G01_2013,
        "Crs": 134.75,
        "DeltaN": 4.12374319903e-9,
        "M0": -2.23037324521,
        "Cuc": 7.25500285625e-6,
        "Eccentricity": 1.61300709005e-2,
        "Cus": 8.00378620625e-6,
        "sqrtA": 5153.71900558,
        "Toe": 424800.0,
        "Cic": 7.07805156708e-8,
        "Omega0": -2.84371723002,
        "Cis": 2.6635825634e-7,
        "Io": 0.967821256634,
        "Crc": 226.75,
        "omega": -1.2251476939,
        "OmegaDot": -7.73246494535e-9,
        "IDOT": 2.60367988229e-10,
        "week": 2304.0,
        "toc_gps_s": 2304 * WEEK_S + 424800.0,
    }
    table = _table(row)
    t = np.array([2304 * WEEK_S + 424830.0])
    st_ = eph.satellite_states(table, np.array([0]), t)
    np.testing.assert_allclose(st_.pos[0], [22151566.575334515, 13275548.286060918, 7260529.645377433], atol=1e-3)


def _gnsstoolbox(row: dict[str, object], t_gps: float, const: str = "G") -> tuple[np.ndarray, float]:
    orbits = pytest.importorskip("gnsstoolbox.orbits")
    o = orbits.orbit()
    o.type = "nav"
    n = orbits.nav_element()
    prn = int(str(row["sat"])[1:])
    names = {
        "alpha0": "SVclockBias", "alpha1": "SVclockDrift", "alpha2": "SVclockDriftRate", "crs": "Crs",
        "delta_n": "DeltaN", "M0": "M0", "cuc": "Cuc", "e": "Eccentricity", "cus": "Cus", "sqrt_a": "sqrtA",
        "TOE": "Toe", "cic": "Cic", "OMEGA": "Omega0", "cis": "Cis", "i0": "Io", "crc": "Crc", "omega": "omega",
        "OMEGA_DOT": "OmegaDot", "IDOT": "IDOT",
    }  # fmt: skip
    for theirs, ours in names.items():
        setattr(n, theirs, float(row[ours]))  # type: ignore[arg-type]
    n.PRN, n.gps_wk, n.sv_health, n.TGD = prn, int(row["week"]), 0, 0.0  # type: ignore[call-overload]
    n.mjd = 44244.0 + float(row["toc_gps_s"]) / 86400.0  # type: ignore[arg-type]
    n.TOC = n.mjd
    getattr(o, "NAV_dataG" if const == "G" else "NAV_dataE")[prn - 1] = [n]
    x, y, z, dte = o.calcSatCoordGPSNav(const, prn, 44244.0 + t_gps / 86400.0)
    return np.array([x, y, z], dtype=float), float(dte)


@pytest.mark.parametrize("dt", [-5400.0, 0.0, 900.0, 7000.0])
def test_gps_matches_gnsstoolbox(dt: float) -> None:
    """Positions agree at the mm level (gnsstoolbox keeps time in MJD: ~1 mm of resolution)."""
    table = _table(G01_2013)
    t = float(G01_2013["toc_gps_s"]) + dt  # type: ignore[arg-type]
    st_ = eph.satellite_states(table, np.array([0]), np.array([t]))
    pos, dte = _gnsstoolbox(G01_2013, t)
    np.testing.assert_allclose(st_.pos[0], pos, atol=3e-3)
    assert st_.clock_s[0] == pytest.approx(dte, abs=1e-14)


def test_galileo_matches_gnsstoolbox_with_its_constants() -> None:
    """gnsstoolbox evaluates Galileo with GPS's μ: with that μ we agree to mm; with Galileo's own
    μ (ICD value 3.986004418e14) the along-track offset grows to ~1 m in 2 h, as expected."""
    table = _table(E11_2013)
    t = float(E11_2013["toc_gps_s"]) + 6800.0  # type: ignore[arg-type]  # gnsstoolbox serves ≤ 2 h from Toc
    gps_mu = replace(table, mu=np.full(1, GPS.mu_m3ps2), f_rel=np.full(1, GPS.f_rel_s_per_sqrtm))
    ours = eph.satellite_states(gps_mu, np.array([0]), np.array([t]))
    pos, dte = _gnsstoolbox(E11_2013, t, "E")
    np.testing.assert_allclose(ours.pos[0], pos, atol=3e-3)
    assert ours.clock_s[0] == pytest.approx(dte, abs=1e-13)
    own = eph.satellite_states(table, np.array([0]), np.array([t]))
    # Δn/n = −½ Δμ/μ → along-track shift ≈ ½·(Δμ/μ)·n·tk·A
    a = float(E11_2013["sqrtA"]) ** 2  # type: ignore[arg-type]
    n = np.sqrt(GALILEO.mu_m3ps2 / a**3)
    expect = 0.5 * (GPS.mu_m3ps2 - GALILEO.mu_m3ps2) / GPS.mu_m3ps2 * n * 6800.0 * a
    assert np.linalg.norm(own.pos[0] - ours.pos[0]) == pytest.approx(expect, rel=0.05)


def test_qzss_and_simulated_constellation_match_gnsstoolbox() -> None:
    """Every system of the simulated constellation (QZSS IGSO e ≈ 0.075 and GEO included)."""
    t0 = 2300 * WEEK_S + 7200.0
    nav = constellation_nav(t0, t0 + 1800.0, seed=4)
    picks = nav.groupby("sat").head(1)
    picks = picks[picks["sat"].isin(["G05", "G17", "J01", "J02", "J03", "J04", "E07"])]
    assert len(picks) == 7
    table = eph.nav_table(picks.reset_index(drop=True))
    for i, row in enumerate(table.sat):
        t = float(table.toe_s[i]) + 1234.5
        rec = picks[picks["sat"] == row].iloc[0].to_dict()
        if row.startswith("E"):
            tab = replace(table, mu=np.full(table.size, GPS.mu_m3ps2), f_rel=np.full(table.size, GPS.f_rel_s_per_sqrtm))
        else:
            tab = table
        ours = eph.satellite_states(tab, np.array([i]), np.array([t]))
        theirs, dte = _gnsstoolbox(rec, t, "E" if row.startswith("E") else "G")
        np.testing.assert_allclose(ours.pos[0], theirs, atol=3e-3, err_msg=row)
        assert ours.clock_s[0] == pytest.approx(dte, abs=1e-13)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 0.9), st.floats(-10.0, 10.0))
def test_kepler_inverts(ecc: float, e_true: float) -> None:
    m = e_true - ecc * np.sin(e_true)
    assert eph.eccentric_anomaly(np.array([m]), np.array([ecc]))[0] == pytest.approx(e_true, abs=1e-12)


def test_kepler_known_value() -> None:
    """e = 0.075 (QZSS), M = 1 rad: the fixed-point iteration E ← M + e sin E (a different method
    from Newton's) converges to 1.0656..."""
    e = eph.eccentric_anomaly(np.array([1.0]), np.array([0.075]))[0]
    assert e - 0.075 * np.sin(e) == pytest.approx(1.0, abs=1e-15)
    fixed = 1.0
    for _ in range(60):
        fixed = 1.0 + 0.075 * np.sin(fixed)
    assert e == pytest.approx(fixed, abs=1e-14)
    assert e == pytest.approx(1.06563, abs=1e-5)


def test_velocity_is_the_derivative_and_relativity() -> None:
    table = _table(G01_2013)
    t = float(G01_2013["toc_gps_s"]) + 600.0  # type: ignore[arg-type]
    ts = np.array([t - 0.5, t, t + 0.5])
    s = eph.satellite_states(table, np.zeros(3, dtype=np.int64), ts)
    np.testing.assert_allclose(s.vel[1], s.pos[2] - s.pos[0], atol=1e-3)
    assert s.clock_rate[1] == pytest.approx(s.clock_s[2] - s.clock_s[0], abs=1e-15)
    rel = GPS.f_rel_s_per_sqrtm * 0.00189499533735200 * 5153.70066070600 * np.sin(s.ecc_anomaly[1])
    assert s.relativistic_s[1] == pytest.approx(rel, rel=1e-12)
    assert abs(C_MPS * rel) < 15.0  # e = 0.0019: up to ~13 m


def test_group_delays() -> None:
    table = _table(G01_2013, E11_2013, {**E11_2013, "DataSrc": 258.0, "BGDe5b": 1e-9})
    freq = np.array([F_L1_HZ, F_L2_HZ, F_L1_HZ, F_L5_HZ])
    tgd = 8.38190317153900e-09
    g = int(np.flatnonzero(table.sat == "G01")[0])
    inav = int(np.flatnonzero((table.sat == "E11") & (table.kind == eph.KIND_INAV))[0])
    fnav = int(np.flatnonzero((table.sat == "E11") & (table.kind == eph.KIND_FNAV))[0])
    gd = eph.group_delay_s(table, np.array([g, g, inav, fnav]), freq)
    np.testing.assert_allclose(gd[:2], [tgd, tgd * (F_L1_HZ / F_L2_HZ) ** 2])
    assert gd[2] == 0.0  # I/NAV E1: BGD(E1, E5b) = 0 in this record
    assert gd[3] == pytest.approx(-6.51925802230800e-09 * (F_L1_HZ / F_L5_HZ) ** 2)


def test_selection_nearest_healthy_within_fit() -> None:
    base = dict(G01_2013)
    recs = []
    for k, toe in enumerate((345600.0, 352800.0, 360000.0)):
        recs.append({**base, "Toe": toe, "toc_gps_s": 1742 * WEEK_S + toe, "health": 1.0 if k == 1 else 0.0})
    table = _table(*recs)
    t0 = 1742 * WEEK_S
    times = t0 + np.array([346000.0, 352900.0, 356500.0, 367100.0, 330000.0])
    idx = eph.select_ephemeris(table, np.full(5, "G01"), times)
    picked = np.where(idx >= 0, table.toe_s[np.maximum(idx, 0)] - t0, -1)
    # 352900: the nearest (352800) is unhealthy → 360000 at 7100 s is inside ±2 h; 330000 is 15600 s from
    # the first Toe: none
    np.testing.assert_array_equal(picked, [345600.0, 360000.0, 360000.0, 360000.0, -1])
    assert eph.select_ephemeris(table, np.array(["G02"]), times[:1])[0] == -1


def test_galileo_falls_back_to_the_other_message() -> None:
    table = _table(E11_2013)  # I/NAV only
    t = np.full(2, float(E11_2013["toc_gps_s"]) + 60.0)  # type: ignore[arg-type]
    idx = eph.select_ephemeris(table, np.array(["E11", "E11"]), t, np.array(["1", "5"]))
    np.testing.assert_array_equal(idx, [0, 0])


def test_sagnac_magnitude() -> None:
    """(Ω̇e/c)(x_s y_r − y_s x_r): a GEO 90° of longitude from an equatorial receiver gives
    Ω̇e·R_E·r_GEO/c ≈ 65 m; GPS satellites give up to ~30 m; sign follows the rotation."""
    rx = np.array([6_378_137.0, 0.0, 0.0])
    geo = np.array([0.0, 42_164_000.0, 0.0])
    s = eph.sagnac_m(geo, rx, GPS.omega_e_radps)
    assert s == pytest.approx(-GPS.omega_e_radps * 42_164_000.0 * 6_378_137.0 / C_MPS, rel=1e-12)
    assert 60.0 < abs(s) < 70.0
    gps = np.array([0.0, 26_560_000.0, 0.0])
    assert 25.0 < abs(float(eph.sagnac_m(gps, rx, GPS.omega_e_radps))) < 45.0


def test_missing_column_is_a_clear_error() -> None:
    with pytest.raises(eph.EphemerisError, match="gnss_nav frame, column 'toc_gps_s': missing column"):
        eph.nav_table(pd.DataFrame({"sat": ["G01"]}))
