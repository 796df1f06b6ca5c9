"""Real Galileo (I/NAV and F/NAV) and QZSS broadcast records (tests/data/rinex/README.md).

* ``CEDA00USA_R_20182100000_01D_MN_excerpt.rnx``: a Septentrio PolaRx5 (UNAVCO station CEDA)
  mixed RINEX 3.03 navigation file, 2018-07-29: eight Galileo records, among them the I/NAV
  (DataSrc 517) and the F/NAV (DataSrc 258) record of E30 and E27 for the same Toe;
* ``BRDC00IGS_R_20191330000_01D_MN_qzss_excerpt.rnx``: the IGS merged broadcast file of
  2019-05-13, its QZSS records: J01, J02 (IGSO, e ≈ 0.075), J03 (IGSO) and J07 (GEO), Toe 00:00 and 02:00.

Each is read with ``logs import`` and our RINEX reader; the fields are checked against the
values read by hand from the file and against georinex; the satellite positions and clocks
against gnsstoolbox, the pattern of ``test_ephemeris`` (gnsstoolbox evaluates Galileo with
GPS's μ and F, so Galileo is compared with those substituted, then the shift that Galileo's
own μ makes is checked against its closed form).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from fieldlogs.gnss import ephemeris as eph
from fieldlogs.gnss.constants import C_MPS, F_L1_HZ, F_L5_HZ, GALILEO, GPS, QZSS, WEEK_S
from fieldlogs.recorders.importer import import_run
from fieldlogs.recorders.rinex import read_rinex
from fieldlogs.runs.handle import read_run
from tests.fieldlogs.gnss.test_ephemeris import _gnsstoolbox
from tests.fieldlogs.gnss.test_real_rinex import _vehicle

DATA = Path(__file__).resolve().parents[2] / "data" / "rinex"
GAL_FILE = DATA / "CEDA00USA_R_20182100000_01D_MN_excerpt.rnx"
QZS_FILE = DATA / "BRDC00IGS_R_20191330000_01D_MN_qzss_excerpt.rnx"
WEEK_2018 = 2012  # GPS week of 2018-07-29 (a Sunday: time of week = seconds of the day)
WEEK_2019 = 2053  # GPS week of 2019-05-13 (a Monday: tow 86400 at 00:00)
MU_GAL_ICD = 3.986004418e14  # Galileo OS SIS ICD §5.1.1, typed here, not taken from the module
MU_GPS_ICD = 3.986005e14  # IS-GPS-200N Table 20-IV (and IS-QZSS-PNT)


def _georinex(path: Path) -> Any:
    georinex = pytest.importorskip("georinex")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its xarray.merge FutureWarnings
        return georinex.load(path)


@pytest.fixture(scope="module")
def gal() -> pd.DataFrame:
    return read_rinex(GAL_FILE).frames["gnss_nav"]


@pytest.fixture(scope="module")
def qzs() -> pd.DataFrame:
    return read_rinex(QZS_FILE).frames["gnss_nav"]


def test_logs_import_keeps_every_galileo_and_qzss_record(tmp_path: Path) -> None:
    """A navigation file alone has no run time base: the files come with a real observation file
    (OPEC, 2022) that gives it; the navigation rows keep their own epochs."""
    obs = DATA / "OPEC00NOR_S_20220010000_01D_30S_MO_excerpt.rnx"
    res = import_run(
        [obs, GAL_FILE, QZS_FILE],
        tmp_path / "run",
        vehicle=_vehicle(tmp_path / "v.toml", "OPEC00NOR_S_20220010000_01D_30S_MO_excerpt", 0.0),
    )
    assert res.rows["gnss_nav"] == 8 + 8
    nav = read_run(tmp_path / "run").stream("gnss_nav")
    assert nav is not None
    assert sorted(nav["sat"].unique()) == ["E02", "E03", "E07", "E08", "E27", "E30", "J01", "J02", "J03", "J07"]
    # the two E30 records of Toe 09:20 are distinct messages, not repeats: both are kept
    e30 = nav[nav["sat"] == "E30"].sort_values("DataSrc")
    assert e30["DataSrc"].tolist() == [258.0, 517.0]


def test_galileo_inav_and_fnav_records_by_hand(gal: pd.DataFrame) -> None:
    """E30, epoch 2018-07-29 09:20:00 GST, the two records as printed in the file."""
    e30 = gal[gal["sat"] == "E30"].set_index("DataSrc")
    inav, fnav = e30.loc[517.0], e30.loc[258.0]
    toc = WEEK_2018 * WEEK_S + 9 * 3600 + 20 * 60
    for r in (inav, fnav):
        assert r["toc_gps_s"] == toc
        assert (r["Toe"], r["week"], r["IODE"], r["SVacc"], r["health"]) == (33600.0, 2012.0, 56.0, 3.12, 0.0)
        assert (r["Crs"], r["DeltaN"], r["M0"]) == (37.59375, 2.546177487084e-09, -1.256783461207)
        assert (r["Cuc"], r["Eccentricity"], r["Cus"], r["sqrtA"]) == (
            1.696869730949e-06,
            1.848770771176e-04,
            1.274421811104e-05,
            5440.613332748,
        )
        assert (r["Cic"], r["Omega0"], r["Cis"]) == (2.421438694e-08, -9.610045645546e-02, -1.024454832077e-07)
        assert (r["Io"], r["Crc"], r["omega"], r["OmegaDot"]) == (
            0.9900571081954,
            79.875,
            1.912889928321,
            -5.123427697043e-09,
        )
        assert (r["IDOT"], r["SVclockDrift"], r["SVclockDriftRate"]) == (-5.510943838646e-10, -3.083755473199e-11, 0.0)
        assert r["BGDe5a"] == -3.259629011154e-09
        assert np.isnan(r["TGD"]) and np.isnan(r["FitIntvl"])  # GPS-only fields
    # the clock differs: I/NAV af0 is for (E1, E5b), F/NAV af0 for (E1, E5a); F/NAV has no BGD(E1, E5b)
    assert (inav["SVclockBias"], inav["BGDe5b"], inav["TransTime"]) == (
        5.639631650411e-03,
        -3.958120942116e-09,
        34949.0,
    )
    assert (fnav["SVclockBias"], fnav["BGDe5b"], fnav["TransTime"]) == (5.639632407110e-03, 0.0, 37627.0)


def test_galileo_records_match_georinex(gal: pd.DataFrame) -> None:
    ds = _georinex(GAL_FILE)
    names = {"IODnav": "IODE", "SISA": "SVacc", "GALWeek": "week"}
    n = 0
    for sv in ds.sv.values:
        sub = ds.sel(sv=sv).dropna("time", how="all")
        for k in range(sub.sizes["time"]):
            rec = sub.isel(time=k)
            t = pd.Timestamp(rec.time.values)
            src = float(rec["DataSrc"])
            ours = gal[(gal["sat"] == str(sv)[:3]) & (gal["DataSrc"] == src)]
            toc = WEEK_2018 * WEEK_S + (t - pd.Timestamp("2018-07-29")).total_seconds()
            ours = ours[ours["toc_gps_s"] == toc]
            assert len(ours) == 1, (sv, t)
            row = ours.iloc[0]
            for var in rec.data_vars:
                col = names.get(str(var), str(var))
                if col in row.index and col != "sat":
                    want = float(rec[var])
                    assert (np.isnan(want) and np.isnan(row[col])) or row[col] == want, (sv, t, var)
            n += 1
    assert n == 8


def test_qzss_records_by_hand_and_against_georinex(qzs: pd.DataFrame) -> None:
    j01 = qzs[qzs["sat"] == "J01"].sort_values("toc_gps_s")
    r = j01.iloc[0]  # J01 2019 05 13 00 00 00
    assert r["toc_gps_s"] == WEEK_2019 * WEEK_S + 86400.0
    assert (r["SVclockBias"], r["SVclockDrift"], r["IODE"], r["Crs"]) == (
        -3.067222423850e-04,
        7.048583938740e-12,
        93.0,
        -160.4375,
    )
    assert (r["Eccentricity"], r["sqrtA"], r["Toe"], r["Io"]) == (
        7.562829146630e-02,
        6493.171686170,
        86400.0,
        0.7201647810220,
    )
    assert (r["week"], r["SVacc"], r["TGD"], r["TransTime"], r["FitIntvl"]) == (
        2053.0,
        2.8,
        -5.122274160390e-09,
        86376.0,
        1.0,
    )
    assert j01.iloc[1]["FitIntvl"] == 0.0  # the 02:00 record: flag 0 (2 h fit)
    ds = _georinex(QZS_FILE)
    for sv in ds.sv.values:
        for k in range(ds.sizes["time"]):
            rec = ds.sel(sv=sv).isel(time=k)
            if np.isnan(float(rec["sqrtA"])):
                continue
            t = pd.Timestamp(rec.time.values)
            toc = WEEK_2019 * WEEK_S + 86400.0 + (t - pd.Timestamp("2019-05-13")).total_seconds()
            row = qzs[(qzs["sat"] == str(sv)) & (qzs["toc_gps_s"] == toc)].iloc[0]
            for var in rec.data_vars:
                col = "week" if var == "GPSWeek" else str(var)
                if col in row.index and col != "sat":
                    want = float(rec[var])
                    assert (np.isnan(want) and np.isnan(row[col])) or row[col] == want, (sv, t, var)


def test_each_system_gets_its_own_icd_constants(gal: pd.DataFrame, qzs: pd.DataFrame) -> None:
    """Galileo OS SIS ICD §5.1.1: μ = 3.986004418e14; IS-GPS-200 and IS-QZSS-PNT: 3.986005e14;
    F = −2√μ/c² per system, so the relativistic F differs in the 8th digit."""
    table = eph.nav_table(pd.concat([gal, qzs], ignore_index=True))
    is_e = table.system == "E"
    assert is_e.sum() == 8 and (table.system == "J").sum() == 8
    assert set(table.mu[is_e]) == {MU_GAL_ICD} and set(table.mu[~is_e]) == {MU_GPS_ICD}
    assert GALILEO.mu_m3ps2 != GPS.mu_m3ps2 and QZSS.mu_m3ps2 == GPS.mu_m3ps2
    for mu, f in ((GALILEO.mu_m3ps2, GALILEO.f_rel_s_per_sqrtm), (GPS.mu_m3ps2, GPS.f_rel_s_per_sqrtm)):
        assert f == pytest.approx(-2.0 * math.sqrt(mu) / C_MPS**2, rel=2e-9)
    assert set(table.f_rel[is_e]) == {GALILEO.f_rel_s_per_sqrtm}
    assert set(table.f_rel[~is_e]) == {QZSS.f_rel_s_per_sqrtm}
    # I/NAV and F/NAV records are told apart by DataSrc and both are selectable
    e30 = np.flatnonzero(table.sat == "E30")
    assert sorted(table.kind[e30].tolist()) == [eph.KIND_INAV, eph.KIND_FNAV]


def _mean_motion_by_hand(sqrt_a: float, delta_n: float, mu: float) -> float:
    return math.sqrt(mu / sqrt_a**6) + delta_n


def test_galileo_mean_motion_by_hand(gal: pd.DataFrame) -> None:
    """E30 at Toe + 1 h: the mean anomaly advances by n·3600 with n from Galileo's μ
    (n0 = √(3.986004418e14 / 5440.613332748⁶) = 1.239725e-4 rad/s, + Δn 2.5e-9); with GPS's μ it would
    be n·t_k·(½·Δμ/μ) = 3.26e-8 rad more, ≈ 0.96 m along the orbit."""
    table = eph.nav_table(gal)
    i = int(np.flatnonzero((table.sat == "E30") & (table.kind == eph.KIND_INAV))[0])
    r = gal[(gal["sat"] == "E30") & (gal["DataSrc"] == 517.0)].iloc[0]
    n = _mean_motion_by_hand(r["sqrtA"], r["DeltaN"], MU_GAL_ICD)
    assert n == pytest.approx(1.239750e-4, rel=1e-6)
    tk = 3600.0
    m = r["M0"] + n * tk
    ecc_anom = m
    for _ in range(50):  # fixed-point iteration, a different method from the module's Newton
        ecc_anom = m + r["Eccentricity"] * math.sin(ecc_anom)
    st_ = eph.satellite_states(table, np.array([i]), np.array([table.toe_s[i] + tk]))
    assert st_.ecc_anomaly[0] == pytest.approx(ecc_anom, abs=1e-12)
    n_gps = _mean_motion_by_hand(r["sqrtA"], r["DeltaN"], MU_GPS_ICD)
    a = r["sqrtA"] ** 2
    assert (n_gps - n) * tk * a == pytest.approx(0.5 * (MU_GPS_ICD - MU_GAL_ICD) / MU_GPS_ICD * n * tk * a, rel=1e-3)
    assert 0.95 < (n_gps - n) * tk * a < 0.98


@pytest.mark.parametrize("dt", [-3000.0, 0.0, 1800.0, 6000.0])
def test_real_galileo_orbits_and_clocks_match_gnsstoolbox(gal: pd.DataFrame, dt: float) -> None:
    """Every real Galileo record, I/NAV and F/NAV: with GPS's μ and F substituted we agree with
    gnsstoolbox at the mm level (position) and 1e-13 s (clock); with Galileo's own constants the
    offset is the closed-form along-track shift ½·(Δμ/μ)·n·t_k·A (±5 %, plus 1 mm)."""
    for k in range(len(gal)):
        rec = {str(c): v for c, v in gal.iloc[k].items()}
        table = eph.nav_table(gal.iloc[[k]].reset_index(drop=True))
        t = float(table.toc_s[0]) + dt
        gps_mu = replace(table, mu=np.full(1, GPS.mu_m3ps2), f_rel=np.full(1, GPS.f_rel_s_per_sqrtm))
        ours = eph.satellite_states(gps_mu, np.array([0]), np.array([t]))
        pos, dte = _gnsstoolbox(rec, t, "E")
        np.testing.assert_allclose(ours.pos[0], pos, atol=3e-3, err_msg=f"{rec['sat']} {rec['DataSrc']}")
        assert ours.clock_s[0] == pytest.approx(dte, abs=1e-13)
        own = eph.satellite_states(table, np.array([0]), np.array([t]))
        a = float(rec["sqrtA"]) ** 2
        n = math.sqrt(MU_GAL_ICD / a**3)
        tk = t - float(table.toe_s[0])
        expect = 0.5 * (MU_GPS_ICD - MU_GAL_ICD) / MU_GPS_ICD * n * abs(tk) * a
        assert abs(np.linalg.norm(own.pos[0] - ours.pos[0]) - expect) <= 0.05 * expect + 1e-3
        # the relativistic term with Galileo's F: F·e·√A·sin E
        assert own.relativistic_s[0] == pytest.approx(
            GALILEO.f_rel_s_per_sqrtm * rec["Eccentricity"] * rec["sqrtA"] * math.sin(own.ecc_anomaly[0]), rel=1e-12
        )


def test_real_galileo_fnav_serves_e5a_and_inav_e1(gal: pd.DataFrame) -> None:
    """E30 at 09:30: an E1 signal takes the I/NAV record and BGD(E1, E5b); an E5a signal the
    F/NAV record (its own af0) and BGD(E1, E5a)·(f_E1/f_E5a)² (Galileo OS SIS ICD §5.1.5)."""
    table = eph.nav_table(gal)
    t = np.full(2, WEEK_2018 * WEEK_S + 9.5 * 3600)
    idx = eph.select_ephemeris(table, np.array(["E30", "E30"]), t, np.array(["1", "5"]))
    assert table.kind[idx].tolist() == [eph.KIND_INAV, eph.KIND_FNAV]
    assert table.field["SVclockBias"][idx].tolist() == [5.639631650411e-03, 5.639632407110e-03]
    gd = eph.group_delay_s(table, idx, np.array([F_L1_HZ, F_L5_HZ]))
    assert gd[0] == -3.958120942116e-09
    assert gd[1] == pytest.approx(-3.259629011154e-09 * (1575.42 / 1176.45) ** 2, rel=1e-12)


@pytest.mark.parametrize("dt", [-3000.0, 0.0, 1800.0, 3500.0])
def test_real_qzss_orbits_and_clocks_match_gnsstoolbox(qzs: pd.DataFrame, dt: float) -> None:
    """IGSO (e ≈ 0.075) and GEO records: QZSS uses the GPS constants, no substitution."""
    for k in range(len(qzs)):
        rec = {str(c): v for c, v in qzs.iloc[k].items()}
        table = eph.nav_table(qzs.iloc[[k]].reset_index(drop=True))
        t = float(table.toc_s[0]) + dt
        ours = eph.satellite_states(table, np.array([0]), np.array([t]))
        pos, dte = _gnsstoolbox(rec, t, "G")
        np.testing.assert_allclose(ours.pos[0], pos, atol=3e-3, err_msg=str(rec["sat"]))
        assert ours.clock_s[0] == pytest.approx(dte, abs=1e-13)
        radius = float(np.linalg.norm(ours.pos[0]))
        assert 3.88e7 < radius < 4.54e7  # a(1 ± e): a ≈ 42,164 km (√A ≈ 6493), e ≤ 0.0757
    j07 = eph.nav_table(qzs[qzs["sat"] == "J07"].reset_index(drop=True))
    geo = eph.satellite_states(j07, np.array([0, 0]), j07.toe_s[0] + np.array([0.0, 3600.0]))
    lon = np.degrees(np.arctan2(geo.pos[:, 1], geo.pos[:, 0]))
    assert np.abs(lon - 127.0).max() < 0.5  # QZS-3 sits at 127° E
