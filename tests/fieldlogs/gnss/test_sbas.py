"""SBAS/MSAS messages: CRC-24Q, hand-packed messages against the decoder, the encoder against the
decoder, stream screening, fast/long-term application with σ_flt, the ionospheric grid."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.gnss.sbas import SbasCorrections
from fieldlogs.gnss.sbas.bits import crc24q_bytes, parity_ok
from fieldlogs.gnss.sbas.grid import pierce_point
from fieldlogs.gnss.sbas.messages import SbasStreamError, read_messages
from fieldlogs.gnss.sbas_tables import band_igps
from fieldlogs.simulate.gnss import sbas_encode as enc

T0 = 1_400_000_000.0  # a GPS time (continuous seconds)


def stream(msgs: list[tuple[float, bytes]], prn: int = 137) -> pd.DataFrame:
    """gnss_sbas rows of (t_of, message): received 1.125 s after their time of applicability."""
    return pd.DataFrame(
        {
            "t": [t - T0 for t, _ in msgs],
            "gnss_time_s": [t + 1.125 for t, _ in msgs],
            "prn": prn,
            "message_hex": [m.hex().upper() for _, m in msgs],
        }
    )


def to_bits(m: bytes) -> np.ndarray:
    return np.unpackbits(np.frombuffer(m, dtype=np.uint8))[None, :]


# --- CRC and bit layouts ---------------------------------------------------------------


def test_crc24q_check_value() -> None:
    # CRC-24Q (poly 0x1864CFB, init 0, no reflection): the catalogue check value of "123456789"
    assert int(crc24q_bytes(np.frombuffer(b"123456789", dtype=np.uint8)[None, :])[0]) == 0xCDE703
    assert enc.crc24q_bits(int.from_bytes(b"123456789", "big"), 72) == 0xCDE703


def test_hand_packed_mt2_decodes_to_its_corrections() -> None:
    # preamble 0x53, MT 2, IODF 1, IODP 0; PRC +1.0 m (8 LSB), -0.5 m (-4 → 0xFFC), +0.125 m, -256 m
    # (0x800), then zeros; UDREI 0, 5, 13, 15 then 15s
    prc = ["000000001000", "111111111100", "000000000001", "100000000000"] + ["0" * 12] * 9
    udrei = ["0000", "0101", "1101", "1111"] + ["1111"] * 9
    body = "01010011" + "000010" + "01" + "00" + "".join(prc) + "".join(udrei)
    assert len(body) == 226
    value = int(body, 2)
    crc = enc.crc24q_bits(value, 226)
    bits = f"{body}{crc:024b}000000"
    msg = int(bits, 2).to_bytes(32, "big")
    assert msg == enc.mt_fast(2, 1, 0, [1.0, -0.5, 0.125, -256.0], [0, 5, 13, 15] + [15] * 9)
    m = read_messages(stream([(T0, msg)]))
    f = m.fast.set_index("slot")
    assert m.dropped == {} and list(f.loc[[1, 2, 3, 4], "prc_m"]) == [1.0, -0.5, 0.125, -256.0]
    assert list(f.loc[[1, 2, 3, 4], "udrei"]) == [0, 5, 13, 15]
    assert (f["iodf"] == 1).all() and (f["iodp"] == 0).all() and f["t_of"].iloc[0] == T0


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    st.lists(st.integers(-2048, 2047), min_size=13, max_size=13),
    st.lists(st.integers(0, 15), min_size=13, max_size=13),
    st.integers(2, 5),
)
def test_fast_corrections_round_trip(codes: list[int], udrei: list[int], mt: int) -> None:
    msg = enc.mt_fast(mt, 2, 3, [c * 0.125 for c in codes], udrei)
    assert parity_ok(to_bits(msg))[0]
    f = read_messages(stream([(T0, msg)])).fast
    assert list(f["prc_m"]) == [c * 0.125 for c in codes] and list(f["udrei"]) == udrei
    assert list(f["slot"]) == list(range(13 * (mt - 2) + 1, 13 * (mt - 2) + 14))


def test_long_term_both_velocity_codes_and_mt24() -> None:
    a = enc.LongTerm(3, 77, 1.25, -2.5, 0.375, 20 * 2.0**-31, 3 * 2.0**-11, -5 * 2.0**-11, 0.0, 2 * 2.0**-39, 4000.0)
    b = enc.LongTerm(4, 12, -1.0, 0.5, 31.875, -7 * 2.0**-31)
    c = enc.LongTerm(5, 13, 0.125, 0.0, -32.0, 0.0)
    msgs = [
        (T0, enc.mt25((True, [a]), (False, [b, c]), 1)),
        (T0 + 1, enc.mt24(1, 2, 1, [0.5] * 6, [4] * 6, (False, [b]))),
    ]
    m = read_messages(stream(msgs))
    lt = m.long_term.set_index(["t_rx", "slot"])
    va = lt.loc[(T0 + 1.125, 3)]
    assert bool(va["velocity"]) and va["iode"] == 77 and va["t0_sod_s"] == 4000.0
    assert (va["dx_m"], va["dy_m"], va["dz_m"], va["daf0_s"]) == (1.25, -2.5, 0.375, 20 * 2.0**-31)
    assert (va["ddx_mps"], va["ddy_mps"], va["daf1_sps"]) == (3 * 2.0**-11, -5 * 2.0**-11, 2 * 2.0**-39)
    for t in (T0 + 1.125, T0 + 2.125):
        vb = lt.loc[(t, 4)]
        assert not bool(vb["velocity"]) and (vb["iode"], vb["dz_m"], vb["daf0_s"]) == (12, 31.875, -7 * 2.0**-31)
    assert lt.loc[(T0 + 1.125, 5)]["dz_m"] == -32.0
    f24 = m.fast[m.fast["mt"] == 24]
    assert list(f24["slot"]) == list(range(14, 20)) and (f24["prc_m"] == 0.5).all() and (f24["iodf"] == 2).all()


def test_masks_degradation_mt10_igp_mask_and_grid_decode() -> None:
    p = enc.Mt10(b_rrc=0.01, c_ltc_v0=0.004, i_ltc_v0=120, c_er=1.5, i_iono=300, rss_udre=1, c_covariance=0.3)
    msgs = [
        (T0, enc.mt1([1, 5, 32, 120], 2)),
        (T0 + 1, enc.mt7(3, 2, [0, 4, 9, 15])),
        (T0 + 2, enc.mt10(p)),
        (T0 + 3, enc.mt18(1, 8, 1, [21, 22, 46, 47])),
        (T0 + 4, enc.mt26(8, 0, [2.0, 4.0, 3.0, None], [1, 2, 3, 4], 1)),
        (T0 + 5, enc.mt6([0, 1, 2, 3], [7] * 51)),
    ]
    m = read_messages(stream(msgs))
    assert list(m.masks["prn"]) == [1, 5, 32, 120] and list(m.masks["slot"]) == [1, 2, 3, 4]
    assert list(m.degradation["ai"].iloc[:4]) == [0, 4, 9, 15] and m.degradation["t_lat_s"].iloc[0] == 3.0
    r = m.mt10.iloc[0]
    assert (r["b_rrc"], r["c_ltc_v0"], r["i_ltc_v0"], r["c_er"], r["rss_udre"]) == pytest.approx(
        (0.01, 0.004, 120, 1.5, 1)
    )
    assert list(m.igp_mask["igp"]) == [21, 22, 46, 47] and list(m.igp_mask["order"]) == [0, 1, 2, 3]
    assert list(m.iono["delay_code"].iloc[:4]) == [16, 32, 24, 511] and list(m.iono["givei"].iloc[:4]) == [1, 2, 3, 4]
    assert list(m.integrity["iodf"].iloc[[0, 13, 26, 39]]) == [0, 1, 2, 3]


# --- the stream ------------------------------------------------------------------------


def test_bad_rows_are_dropped_and_counted() -> None:
    good = enc.mt1([1, 2], 0).hex()
    flipped = bytearray(bytes.fromhex(good))
    flipped[10] ^= 0x10
    bad_pre = bytearray(bytes.fromhex(good))
    bad_pre[0] = 0x00
    frame = pd.DataFrame(
        {
            "t": range(7),
            "gnss_time_s": T0 + np.arange(7.0),
            "prn": [137, 137, 137, 100, 137, 137, 129],
            "msg_type": [1, 1, 1, 1, 1, 2, 1],
            "message_hex": [good, good[:40], flipped.hex(), good, bad_pre.hex(), good, good],
            "valid": [1, 1, 1, 1, 1, 1, 0],
        }
    )
    m = read_messages(frame)
    assert m.dropped == {"bad_length": 1, "bad_crc": 1, "bad_prn": 1, "bad_preamble": 1, "type_mismatch": 1,
                         "receiver_flagged_invalid": 1}  # fmt: skip
    assert m.n_valid == 1 and m.geo == 137
    with pytest.raises(SbasStreamError, match="gnss_sbas frame, column 'message_hex': missing column"):
        read_messages(frame.drop(columns="message_hex"))


# --- fast and long-term corrections ----------------------------------------------------


def _setup(mt10: bool = True, udrei2: int = 15) -> list[tuple[float, bytes]]:
    lt = enc.LongTerm(1, 7, 1.0, -2.0, 0.5, 10 * 2.0**-31)
    msgs = [
        (T0, enc.mt1([1, 2], 1)),
        (T0 + 1, enc.mt7(0, 1, [0, 0])),
        (T0 + 2, enc.mt25((False, [lt]), (False, []), 1)),
    ]
    if mt10:
        msgs.append((T0 + 3, enc.mt10(enc.Mt10())))
    msgs.append((T0 + 4, enc.mt_fast(2, 1, 1, [1.5, 3.0], [0, udrei2])))
    return msgs


def test_fast_and_long_term_applied_with_iode_matching_and_timeouts() -> None:
    sb = SbasCorrections.from_stream(stream(_setup()))
    t = np.array([T0 + 6, T0 + 6, T0 + 6, T0 + 4 + 181.0, T0 + 6])
    out = sb.rows(np.array(["G01", "G01", "G02", "G01", "G03"]), t, np.array([7.0, 8.0, 7.0, 7.0, 7.0]))
    assert list(out.present) == [True, False, False, False, False]
    assert out.prc_m[0] == 1.5 and list(out.dpos_m[0]) == [1.0, -2.0, 0.5] and out.dclock_s[0] == 10 * 2.0**-31
    assert out.sigma_m[0] == pytest.approx(np.sqrt(0.0520))  # UDREI 0, a = 0, MT 10 all zero
    assert list(out.usable) == [True, True, False, True, True]  # G02: UDREI 15 "do not use"
    assert sb.counts["refused_udrei"] == 1 and sb.counts["no_long_term"] == 1


def test_without_mt10_sigma_flt_gets_8_m_and_stale_udrei_is_not_applied() -> None:
    sb = SbasCorrections.from_stream(stream(_setup(mt10=False, udrei2=14)))
    out = sb.rows(np.array(["G01", "G01", "G02"]), np.array([T0 + 6, T0 + 4 + 19.0, T0 + 6]), np.array([7.0, 7.0, 7.0]))
    assert out.sigma_m[0] == pytest.approx(np.sqrt(0.0520) + 8.0)
    assert not out.present[1] and sb.counts["udrei_timed_out"] == 1  # UDREI older than 18 s
    assert not out.usable[2]  # UDREI 14: not monitored


def test_range_rate_from_successive_fast_corrections_and_mt0() -> None:
    msgs = _setup()
    msgs.append((T0 + 10, enc.mt_fast(2, 2, 1, [2.25, 3.0], [0, 15])))
    sb = SbasCorrections.from_stream(stream(msgs))
    out = sb.rows(np.array(["G01"]), np.array([T0 + 13.0]), np.array([7.0]))
    assert out.prc_m[0] == pytest.approx(2.25 + 0.125 * 3.0)  # RRC (2.25 - 1.5)/6 s
    sb = SbasCorrections.from_stream(stream([*msgs, (T0 + 11, enc.mt0())]))
    assert not sb.rows(np.array(["G01"]), np.array([T0 + 13.0]), np.array([7.0])).present[0]


def test_no_valid_message_is_the_standalone_case() -> None:
    bad = stream(_setup())
    bad["message_hex"] = bad["message_hex"].str[:-8] + "00000000"
    sb = SbasCorrections.from_stream(bad)
    assert sb.empty and sb.messages.dropped["bad_crc"] == len(bad)
    out = sb.rows(np.array(["G01"]), np.array([T0 + 6.0]), np.array([7.0]))
    assert not out.present.any() and out.usable.all() and np.isnan(out.sigma_m).all()


# --- ionospheric grid ------------------------------------------------------------------


def test_band_tables_and_a_hand_located_igp() -> None:
    assert [band_igps(b)[0].size for b in range(9)] == [201] * 8 + [200]
    lat, lon = band_igps(8)
    assert (lat[20], lon[20]) == (35, 140) and (lat[45], lon[45]) == (35, 145)  # IGPs 21 and 46


def test_pierce_point_and_obliquity_by_hand() -> None:
    lat, lon, f = pierce_point(np.radians([36.0]), np.radians([141.0]), np.radians([0.0]), np.radians([90.0]))
    assert np.degrees(lat[0]) == pytest.approx(36.0) and np.degrees(lon[0]) == pytest.approx(141.0) and f[0] == 1.0
    # E = 30°: R_e cos E/(R_e + h_I) = 6378.1363·0.8660254/6728.1363 = 0.8209745; F = 1/√(1 − 0.6739991) = 1.751421
    _, _, f30 = pierce_point(np.radians([36.0]), np.radians([141.0]), np.radians([0.0]), np.radians([30.0]))
    assert f30[0] == pytest.approx(1.751421, rel=1e-6)
    # due north at E = 30°: ψ = 90° − 30° − asin(0.8209745) = 60° − 55.18246° = 4.81754° of latitude
    lat30, lon30, _ = pierce_point(np.radians([36.0]), np.radians([141.0]), np.radians([0.0]), np.radians([30.0]))
    assert np.degrees(lat30[0]) == pytest.approx(36.0 + 4.81754, abs=1e-4) and np.degrees(lon30[0]) == pytest.approx(
        141.0
    )


def _grid(delays: dict[int, float | None]) -> SbasCorrections:
    # band 8: IGP 21 (35N 140E), 22 (40N 140E), 46 (35N 145E), 47 (40N 145E)
    order = sorted(delays)
    return SbasCorrections.from_stream(
        stream([(T0, enc.mt18(1, 8, 0, order)), (T0 + 1, enc.mt26(8, 0, [delays[k] for k in order], [0] * 4, 0))])
    )


def test_bilinear_and_triangle_interpolation_worked_by_hand() -> None:
    # user at 36N 141E, satellite at the zenith: pierce point = user, x = y = 0.2 in the 5° cell
    args = (
        np.radians([36.0]),
        np.radians([141.0]),
        np.zeros(1),
        np.radians([90.0]),
        np.array([T0 + 10.0]),
        np.array([1.57542e9]),
    )
    sb = _grid({21: 2.0, 46: 3.0, 47: 9.0, 22: 4.0})  # SW 2, SE 3, NE 9, NW 4
    cov, d, s = sb.iono(*args)
    # 0.8·0.8·2 + 0.2·0.8·3 + 0.2·0.2·9 + 0.8·0.2·4 = 1.28 + 0.48 + 0.36 + 0.64
    assert cov[0] and d[0] == pytest.approx(2.76)
    assert s[0] == pytest.approx(np.sqrt(0.0084))  # GIVEI 0 everywhere: Σ W σ² = σ²
    sb = _grid({21: 2.0, 46: 3.0, 47: None, 22: 4.0})  # NE "do not use": triangle SW (right angle), SE, NW
    cov, d, _ = sb.iono(*args)
    assert cov[0] and d[0] == pytest.approx(0.6 * 2.0 + 0.2 * 3.0 + 0.2 * 4.0)
    # a pierce point outside the remaining triangle (x = y = 0.8, near the missing NE corner): no 5° cell,
    # no 10° cell either (its corners are not in the mask) → not covered
    cov, _, _ = sb.iono(np.radians([39.0]), np.radians([144.0]), *args[2:])
    assert not cov[0]
    # grid older than 600 s: not covered
    cov, _, _ = sb.iono(*args[:4], np.array([T0 + 700.0]), args[5])
    assert not cov[0]
