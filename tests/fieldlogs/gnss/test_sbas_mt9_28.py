"""MT 9, 12, 17, 27 and 28: hand-packed messages through the encoder, the decoder at bit positions
counted by hand from the DO-229 layouts, and δUDRE (MT 27 regions, MT 28 covariance) worked by
hand into σ_flt."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fieldlogs.gnss.sbas import SbasCorrections
from fieldlogs.gnss.sbas.bits import getbits, getbitu, parity_ok
from fieldlogs.gnss.sbas.delta_udre import DELTA_UDRE, DeltaUdre, in_region
from fieldlogs.gnss.sbas.messages import read_messages
from fieldlogs.simulate.gnss import sbas_encode as enc

T0 = 1_400_000_000.0


def stream(msgs: list[tuple[float, bytes]], prn: int = 137) -> pd.DataFrame:
    return pd.DataFrame(
        {"t": [t - T0 for t, _ in msgs], "gnss_time_s": [t + 1.125 for t, _ in msgs], "prn": prn,
         "message_hex": [m.hex().upper() for _, m in msgs]}
    )  # fmt: skip


def to_bits(m: bytes) -> np.ndarray:
    return np.unpackbits(np.frombuffer(m, dtype=np.uint8))[None, :]


GEO = enc.GeoNav(
    t0_sod_s=43_200.0, ura=2, x_m=-32_000_000.08, y_m=27_000_000.16, z_m=-1_200.4, vx_mps=1.25, vy_mps=-0.000625,
    vz_mps=-0.5, ax_mps2=0.0000125, ay_mps2=-0.000025, az_mps2=0.0000625, af0_s=-5 * 2.0**-31, af1_sps=3 * 2.0**-40,
)  # fmt: skip


def test_mt9_fields_at_the_hand_counted_bit_positions() -> None:
    m = enc.mt9(GEO)
    b = to_bits(m)
    assert parity_ok(b)[0] and getbitu(b, 8, 6)[0] == 9
    # reserved 14–21, t0 22 (13), URA 35 (4), X 39 (30), Y 69 (30), Z 99 (25), Ẋ 124 (17), Ẏ 141 (17),
    # Ż 158 (18), Ẍ 176 (10), Ÿ 186 (10), Z̈ 196 (10), af0 206 (12), af1 218 (8): 226
    assert getbitu(b, 22, 13)[0] == 2700 and getbitu(b, 35, 4)[0] == 2
    assert getbits(b, 39, 30)[0] == -400_000_001 and getbits(b, 69, 30)[0] == 337_500_002
    assert getbits(b, 99, 25)[0] == -3001 and getbits(b, 124, 17)[0] == 2000 and getbits(b, 141, 17)[0] == -1
    assert getbits(b, 158, 18)[0] == -125 and getbits(b, 176, 10)[0] == 1 and getbits(b, 186, 10)[0] == -2
    assert getbits(b, 196, 10)[0] == 1 and getbits(b, 206, 12)[0] == -5 and getbits(b, 218, 8)[0] == 3
    nav = read_messages(stream([(T0, m)])).geo_nav
    assert len(nav) == 1
    row = nav.iloc[0]
    for name in ("t0_sod_s", "ura", "x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps", "af0_s", "af1_sps"):
        assert row[name] == pytest.approx(getattr(GEO, name), rel=1e-12, abs=1e-15), name


def test_mt12_and_mt17_round_trip() -> None:
    nt = enc.NetworkTime(a1_sps=-7 * 2.0**-50, a0_s=12 * 2.0**-30, t0t_s=4096 * 37, wn_t=201, dt_ls=18, wn_lsf=137,
                         dn=7, dt_lsf=18, utc_id=2, gps_tow_s=345_600, gps_week=285, glonass=1,
                         glonass_da_s=-3 * 2.0**-31)  # fmt: skip
    alm = [
        enc.GeoAlmanac(129, 0, 2600.0 * -5000, 2600.0 * 12000, 26000.0 * -3, 10.0, -20.0, 60.0, data_id=0),
        enc.GeoAlmanac(137, 8, 2600.0 * 4000, 2600.0 * -9000, 0.0, 0.0, 30.0, -120.0),
    ]
    msg = read_messages(stream([(T0, enc.mt12(nt)), (T0 + 1, enc.mt17(alm, 64.0 * 1234))]))
    assert msg.not_decoded == {}
    r = msg.network_time.iloc[0]
    for name in ("a1_sps", "a0_s", "t0t_s", "wn_t", "dt_ls", "wn_lsf", "dn", "dt_lsf", "utc_id", "gps_tow_s",
                 "gps_week", "glonass", "glonass_da_s"):  # fmt: skip
        assert r[name] == pytest.approx(getattr(nt, name), abs=1e-15), name
    a = msg.almanacs
    assert a["prn"].tolist() == [129, 137] and (a["t0_sod_s"] == 64.0 * 1234).all()  # the empty third dropped
    assert a["x_m"].tolist() == [-13_000_000.0, 10_400_000.0] and a["vz_mps"].tolist() == [60.0, -120.0]
    assert a["health"].tolist() == [0, 8] and a["z_m"].tolist() == [-78_000.0, 0.0]


def test_mt27_and_mt28_at_the_hand_counted_bit_positions() -> None:
    m = enc.mt27(5, 2, 2, 3, 4, 9, [enc.Region(30, 125, 45, 150, True), enc.Region(-10, -170, 20, 170, False)])
    b = to_bits(m)
    # IODS 14 (3), count−1 17 (3), number−1 20 (3), regions 23 (3), priority 26 (2), inside 28 (4),
    # outside 32 (4), region k at 36 + 35k: lat1 8, lon1 9, lat2 8, lon2 9, shape 1
    assert [getbitu(b, p, n)[0] for p, n in ((14, 3), (17, 3), (20, 3), (23, 3), (26, 2), (28, 4), (32, 4))] == [
        5, 1, 1, 2, 3, 4, 9]  # fmt: skip
    assert getbits(b, 71, 8)[0] == -10 and getbits(b, 79, 9)[0] == -170 and getbitu(b, 105, 1)[0] == 0
    assert getbitu(b, 70, 1)[0] == 1 and getbits(b, 96, 9)[0] == 170
    cov = enc.Covariance(9, 6, 3, 0, 0, 4, -1, 0, 2, 0, 0, 0)
    b = to_bits(enc.mt28(2, [cov]))
    # IODP 14 (2); satellite at 16: slot 6, exponent 3, E11…E44 9 each, E12…E34 10 each (105 bits)
    assert getbitu(b, 14, 2)[0] == 2 and getbitu(b, 16, 6)[0] == 9 and getbitu(b, 22, 3)[0] == 6
    assert getbitu(b, 25, 9)[0] == 3 and getbitu(b, 52, 9)[0] == 4 and getbits(b, 61, 10)[0] == -1
    assert getbits(b, 81, 10)[0] == 2 and getbitu(b, 121, 6)[0] == 0
    msg = read_messages(stream([(T0, enc.mt27(5, 1, 1, 0, 1, 2, [])), (T0 + 1, enc.mt28(2, [cov]))]))
    assert msg.not_decoded == {} and msg.service["region"].tolist() == [-1]
    c = msg.covariance.iloc[0]
    assert (c["slot"], c["scale_exponent"], c["e11"], c["e44"], c["e12"], c["e14"]) == (9, 6, 3, 4, -1, 2)


def test_region_membership_worked_by_hand() -> None:
    sq = pd.Series({"lat1": 30, "lon1": 125, "lat2": 45, "lon2": 150, "square": True})
    assert in_region(np.array([36.0, 29.0, 45.0]), np.array([140.0, 140.0, 150.0]), sq).tolist() == [True, False, True]
    # triangle (30 N 125 E), (45 N 150 E), right angle at (30 N 150 E): below the hypotenuse from
    # corner 1 to corner 2 — at 137.5 E (halfway) the hypotenuse is at 37.5 N
    tri = sq.copy()
    tri["square"] = False
    got = in_region(np.array([37.0, 38.0, 44.0, 31.0, 31.0]), np.array([137.5, 137.5, 149.0, 149.0, 126.0]), tri)
    assert got.tolist() == [True, False, True, True, False]  # near corner 1 the triangle is thin
    # across the date line: 170 E → 170 W is 20° wide
    wrap = pd.Series({"lat1": -10, "lon1": 170, "lat2": 20, "lon2": -170, "square": True})
    assert in_region(np.array([0.0, 0.0]), np.array([179.0, -160.0]), wrap).tolist() == [True, False]


def _mask_and_mt10(c_cov: float = 0.0) -> list[tuple[float, bytes]]:
    return [(T0, enc.mt1([3, 9], 2)), (T0 + 1, enc.mt10(enc.Mt10(c_covariance=c_cov)))]


def test_mt28_delta_udre_worked_by_hand() -> None:
    # slot 2 = G09; exponent 5: SF = 1 m; R = [[3, 0, 0, 2], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 4]]
    cov = enc.Covariance(2, 5, 3, 0, 0, 4, 0, 0, 2, 0, 0, 0)
    msg = read_messages(stream([*_mask_and_mt10(0.5), (T0 + 2, enc.mt28(2, [cov]))]))
    du = DeltaUdre.build(msg)
    t = np.full(3, T0 + 10.0)
    los = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    d = du.factor(np.array(["G09", "G09", "G03"]), t, np.zeros(3), np.zeros(3), los)
    # ê = x: R·I = (3 + 2, 0, 0, 4) → √41; ê = y: (2, 0, 0, 4) → √20; + ε_c = 0.5·SF; G03 has none
    assert d.tolist() == pytest.approx([np.sqrt(41.0) + 0.5, np.sqrt(20.0) + 0.5, 1.0])
    late = du.factor(np.array(["G09"]), np.array([T0 + 2 + 1.125 + 241.0]), np.zeros(1), np.zeros(1), los[:1])
    assert late[0] == 1.0  # MT 28 timed out after 240 s
    # exponent 7: SF = 4 m scales R and ε_c
    cov4 = enc.Covariance(2, 7, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    msg4 = read_messages(stream([*_mask_and_mt10(0.5), (T0 + 2, enc.mt28(2, [cov4]))]))
    assert DeltaUdre.build(msg4).factor(np.array(["G09"]), t[:1], np.zeros(1), np.zeros(1), los[:1])[0] == 4.0 + 2.0


def test_mt27_delta_udre_inside_outside_priority_and_incomplete_sets() -> None:
    japan = enc.Region(30, 125, 45, 150, True)
    kyushu = enc.Region(30, 128, 35, 133, True)
    one = enc.mt27(1, 2, 1, 1, 2, 9, [japan])  # δUDRE 1.25 inside, 8 outside; priority 1
    two = enc.mt27(1, 2, 2, 2, 5, 7, [kyushu])  # δUDRE 3 inside, 5 outside; priority 2
    lat, lon = np.array([36.0, 32.0, 10.0]), np.array([140.0, 130.0, 100.0])
    t = np.full(3, T0 + 20.0)
    half = DeltaUdre.build(read_messages(stream([*_mask_and_mt10(), (T0 + 2, one)])))
    assert half.factor(np.full(3, "G03"), t, lat, lon, np.ones((3, 3))).tolist() == [8.0] * 3  # incomplete: max
    full = DeltaUdre.build(read_messages(stream([*_mask_and_mt10(), (T0 + 2, one), (T0 + 3, two)])))
    got = full.factor(np.full(3, "G03"), t, lat, lon, np.ones((3, 3)))
    # Tokyo: only message 1's region → 1.25; Kyushu: both, priority 2 wins → 3; outside both: the
    # highest priority's outside value → 5
    assert got.tolist() == [DELTA_UDRE[2], DELTA_UDRE[5], DELTA_UDRE[7]] == [1.25, 3.0, 5.0]


def test_delta_udre_scales_sigma_udre_in_sigma_flt() -> None:
    lt = enc.LongTerm(2, 7, 0.0, 0.0, 0.0, 0.0)
    base = [
        (T0, enc.mt1([3, 9], 1)),
        (T0 + 1, enc.mt7(0, 1, [0, 0])),
        (T0 + 2, enc.mt25((False, [lt]), (False, []), 1)),
        (T0 + 3, enc.mt10(enc.Mt10(c_ltc_lsb=0.0))),
        (T0 + 4, enc.mt27(1, 1, 1, 0, 4, 4, [])),  # δUDRE 2 everywhere
        (T0 + 5, enc.mt_fast(2, 1, 1, [0.0, 1.0], [15, 3])),
    ]
    sb = SbasCorrections.from_stream(stream(base))
    rows = sb.rows(np.array(["G09"]), np.array([T0 + 8.0]), np.array([7.0]))
    assert rows.present[0] and rows.udre_sigma_m is not None and rows.udre_rss is not None
    s_udre = np.sqrt(0.2830)  # UDREI 3
    assert rows.udre_sigma_m[0] == pytest.approx(s_udre) and rows.sigma_m[0] == pytest.approx(s_udre)
    out = sb.flt_sigma(rows.sigma_m, rows.udre_sigma_m, rows.udre_rss, np.array(["G09"]), np.array([T0 + 8.0]),
                       np.radians([36.0]), np.radians([140.0]), np.array([[0.0, 0.0, 1.0]]))  # fmt: skip
    assert out[0] == pytest.approx(2.0 * s_udre)
    where = (np.array([T0 + 8.0]), np.radians([36.0]), np.radians([140.0]), np.array([[0.0, 0.0, 1.0]]))
    rss = sb.flt_sigma(np.array([1.0]), np.array([s_udre]), np.array([True]), np.array(["G09"]), *where)
    assert rss[0] == pytest.approx(np.sqrt(1.0 + s_udre**2 * 3.0))  # √(σ² + σ²_UDRE(δ² − 1))
