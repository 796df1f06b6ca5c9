"""UBX: the writer read back by pyubx2 and by the reader; bad checksums, stray bytes,
truncated files; ESF axes, units and the drifting sensor clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pyubx2 import UBXReader

from fieldlogs.recorders.ubx import frame, read_ubx, write_ubx
from schemas.errors import InputError
from schemas.gnss import GNSS_NAV
from tests.fieldlogs.recorders.conftest import T0_GPS, gps_frame, nav_row, obs_frame


def _pyubx2(path: Path) -> list[object]:
    with path.open("rb") as fh:
        return [m for _, m in UBXReader(fh, protfilter=2)]


def _sensors(n_s: float = 20.0, t0: float = T0_GPS) -> tuple[pd.DataFrame, pd.DataFrame]:
    ti = t0 + np.arange(0.0, n_s, 0.01)
    imu = pd.DataFrame({"gnss_time_s": ti, "ax": 0.25, "ay": -0.5, "az": 9.75, "wx": 0.01, "wy": -0.02, "wz": 0.05})
    tt = t0 + np.arange(0.0, n_s, 0.1)
    # a counter that wraps at 2^23 on the way
    tacho = pd.DataFrame({"gnss_time_s": tt, "pulses": (2**23 - 50) + 7 * np.arange(len(tt))})
    return imu, tacho


def test_gnss_round_trip_through_pyubx2_and_the_reader(tmp_path: Path) -> None:
    gps, obs, nav = gps_frame(20), obs_frame(20, receiver="rx1"), pd.DataFrame([nav_row("G07"), nav_row("J02")])
    p = tmp_path / "rx1.ubx"
    write_ubx(p, gps=gps, obs=obs, nav=nav)
    msgs = _pyubx2(p)
    pvt = [m for m in msgs if m.identity == "NAV-PVT"]
    raw = [m for m in msgs if m.identity == "RXM-RAWX"]
    assert len(pvt) == 20 and len(raw) == 20
    assert [m.identity for m in msgs].count("RXM-SFRBX") == 6
    np.testing.assert_allclose([m.lat for m in pvt], gps["lat"], atol=1.1e-7)
    assert [m.numSV for m in pvt] == gps["nsat"].tolist()
    assert raw[0].numMeas == 7 and raw[0].prMes_01 == pytest.approx(obs["pseudorange_m"].iloc[0])

    dec = read_ubx(p)
    back = dec.frames["gps"]
    np.testing.assert_allclose(back["gnss_time_s"], gps["gnss_time_s"], atol=1e-6)
    np.testing.assert_allclose(back["lat"], gps["lat"], atol=1e-9)  # HPPOSLLH: 1e-9 deg
    np.testing.assert_allclose(back["lon"], gps["lon"], atol=1e-9)
    np.testing.assert_allclose(back["height_m"], gps["height_m"], atol=1e-4)
    np.testing.assert_allclose(back["hdop"], gps["hdop"], atol=0.005)
    assert back["fix"].tolist() == gps["fix"].tolist()
    np.testing.assert_allclose(back["sigma_lat_m"], gps["sigma_lat_m"], atol=1e-3)

    o = dec.frames["gnss_obs"]
    key = ["gnss_time_s", "sat", "signal"]
    a, b = obs.sort_values(key).reset_index(drop=True), o.sort_values(key).reset_index(drop=True)
    assert b[key].equals(a[key]) and (b["receiver"] == "rx1").all()
    np.testing.assert_allclose(b["pseudorange_m"], a["pseudorange_m"], atol=1e-6)
    np.testing.assert_allclose(b["carrier_cycles"], a["carrier_cycles"], atol=1e-6)
    np.testing.assert_allclose(b["doppler_hz"], a["doppler_hz"], rtol=1e-7)  # R4
    np.testing.assert_allclose(b["cn0_dbhz"], a["cn0_dbhz"], atol=0.5)  # whole dB-Hz
    assert b["lli"].tolist() == a["lli"].tolist()

    nv = dec.frames["gnss_nav"].set_index("sat")
    for sat in ("G07", "J02"):
        want = nav_row(sat)
        for c in GNSS_NAV.column_names[1:]:
            if isinstance(want[c], float) and np.isnan(want[c]):
                assert np.isnan(nv.loc[sat, c]), (sat, c)
            else:
                assert nv.loc[sat, c] == pytest.approx(want[c], rel=1e-15, abs=1e-25), (sat, c)


def test_ionosphere_and_utc_from_subframe_4(tmp_path: Path) -> None:
    gnss = {
        "klobuchar_alpha": [18 * 2.0**-30, 15 * 2.0**-27, -(2.0**-24), -2 * 2.0**-24],
        "klobuchar_beta": [59 * 2.0**11, 8 * 2.0**14, -2 * 2.0**16, -3 * 2.0**16],
        "leap_seconds": 18,
        "time_corrections": [
            {"type": "GPUT", "a0_s": -5 * 2.0**-30, "a1_s_per_s": -7 * 2.0**-50, "t_ref_s": 61_440.0, "week": 2447.0}
        ],
    }
    p = tmp_path / "rx.ubx"
    write_ubx(p, gps=gps_frame(3), obs=obs_frame(3), gnss=gnss)
    dec = read_ubx(p)
    assert dec.gnss == gnss
    assert "SFRBX LNAV almanac subframes not decoded" not in dec.skipped


def test_esf_axes_units_and_a_drifting_clock(tmp_path: Path) -> None:
    imu, tacho = _sensors()
    gps = gps_frame(20)
    p = tmp_path / "rx.ubx"
    write_ubx(p, gps=gps, imu=imu, tacho=tacho, esf_drift=0.006)
    raw = [m for m in _pyubx2(p) if m.identity == "ESF-RAW"]
    assert len(raw) == len(imu)
    dec = read_ubx(p)
    assert dec.clock is not None
    assert dec.clock["tick_s"] == 1e-3
    assert dec.clock["drift"] == pytest.approx(0.006, abs=2e-5)
    assert dec.clock["residual_max_s"] < 1.5e-3  # ms time tags
    got = dec.frames["imu"]
    np.testing.assert_allclose(got["gnss_time_s"], imu["gnss_time_s"], atol=2e-3)
    np.testing.assert_allclose(got[["ax", "ay", "az"]], imu[["ax", "ay", "az"]], atol=2**-10)
    np.testing.assert_allclose(got[["wx", "wy", "wz"]], imu[["wx", "wy", "wz"]], atol=np.radians(2**-12))
    t = dec.frames["tacho"]
    np.testing.assert_array_equal(t["pulses"] - t["pulses"].iloc[0], tacho["pulses"] - tacho["pulses"].iloc[0])
    assert (np.diff(t["pulses"]) >= 0).all()


def test_esf_sensor_frame_is_forward_right_down(tmp_path: Path) -> None:
    """A hand-built ESF-RAW sample: +1 g on the u-blox z axis (down) is az = −9.81 m/s²
    in the body frame (z up); +1 deg/s about u-blox z (down) is wz = −0.01745 rad/s."""
    gps = gps_frame(3)
    words = [(18 << 24) | (1024 * 10), (5 << 24) | 4096, (17 << 24) | ((1 << 24) - 512)]  # 10 m/s², 1 deg/s, −0.5
    esf = b"".join(
        frame(0x10, 0x03, bytes(4) + np.array([[w, 1000 * k] for w in words], dtype="<u4").tobytes()) for k in range(3)
    )
    pvt = tmp_path / "g.ubx"
    write_ubx(pvt, gps=gps)
    blob = pvt.read_bytes()
    n = len(blob) // 3  # three epochs of equal size: put each ESF sample before its epoch
    p = tmp_path / "hand.ubx"
    parts = [esf[i * len(esf) // 3 : (i + 1) * len(esf) // 3] + blob[i * n : (i + 1) * n] for i in range(3)]
    p.write_bytes(b"".join(parts))
    imu = read_ubx(p).frames["imu"]
    assert imu["az"].iloc[0] == -10.0
    assert imu["ay"].iloc[0] == 0.5
    assert imu["wz"].iloc[0] == pytest.approx(-np.radians(1.0))


def test_bad_checksum_and_stray_bytes_are_counted(tmp_path: Path) -> None:
    p = tmp_path / "rx.ubx"
    write_ubx(p, gps=gps_frame(5))
    blob = bytearray(p.read_bytes())
    size = len(blob) // 5
    blob[size + 20] ^= 0xFF  # damage the second epoch's NAV-PVT payload
    text = b"$GNGGA,junk*00\r\n"
    q = tmp_path / "damaged.ubx"
    q.write_bytes(text + bytes(blob))
    dec = read_ubx(q)
    assert dec.skipped["UBX frames with a bad checksum"] == 1
    assert dec.skipped["bytes outside valid UBX frames (NMEA, damaged frames)"] >= len(text)
    assert len(dec.frames["gps"]) == 4


def test_truncated_file_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "rx.ubx"
    write_ubx(p, gps=gps_frame(3), obs=obs_frame(3))
    q = tmp_path / "cut.ubx"
    q.write_bytes(p.read_bytes()[:-30])
    with pytest.raises(InputError, match="truncated UBX file: the frame at byte") as exc:
        read_ubx(q)
    assert exc.value.path == str(q)


def test_not_ubx(tmp_path: Path) -> None:
    p = tmp_path / "x.ubx"
    p.write_bytes(b"\x00" * 100)
    with pytest.raises(InputError, match="no valid UBX frame"):
        read_ubx(p)


def test_fast_and_general_framing_agree(tmp_path: Path) -> None:
    from fieldlogs.recorders.ubx import _candidates, _chain, _fast_chain

    p = tmp_path / "rx.ubx"
    imu, tacho = _sensors(3.0)
    write_ubx(p, gps=gps_frame(3), obs=obs_frame(3), nav=pd.DataFrame([nav_row()]), imu=imu, tacho=tacho)
    arr = np.frombuffer(p.read_bytes(), dtype=np.uint8)
    fast = _fast_chain(arr)
    s, end, ok = _candidates(arr)
    general, stray, bad, trunc = _chain(s, end, ok, len(arr))
    assert fast is not None and fast == general and (stray, bad, trunc) == (0, 0, None)
    damaged = arr.copy()
    damaged[fast[5] + 7] ^= 0x01  # one payload bit of the sixth frame
    assert _fast_chain(damaged) is None


def test_hand_made_file(data: Path) -> None:
    """tests/data/recorders/sample.ubx, packed by hand with struct (u-blox field order): two
    NAV-PVT (the second sent twice, first with a damaged byte), an NMEA line between frames,
    one RXM-RAWX with G07 and E11."""
    dec = read_ubx(data / "sample.ubx")
    gps = dec.frames["gps"]
    assert gps["gnss_time_s"].tolist() == [T0_GPS, T0_GPS + 1.0]  # 2026-12-01 10:00:00 UTC, iTOW 208 818 s
    assert gps["lat"].tolist() == [35.9070517, 35.9070527]
    assert gps["lon"].tolist() == [139.4830967, 139.4831067]
    assert gps["fix"].tolist() == [2, 1]  # diffSoln set in the first only
    assert gps["nsat"].tolist() == [12, 11]
    assert gps["height_m"].tolist() == [63.5, 63.6]
    assert gps["sigma_lat_m"].tolist() == [0.45, 0.52]
    np.testing.assert_allclose(gps[["speed_mps", "course_deg"]], [[10.0, 90.0], [10.1, 90.0]], rtol=1e-12)
    assert gps["hdop"].isna().all()  # no NAV-DOP in the file
    assert dict(dec.skipped) == {
        "UBX frames with a bad checksum": 1,
        "bytes outside valid UBX frames (NMEA, damaged frames)": len(b"$GNTXT,01,01,02,hand-made*00\r\n") + 8 + 92,
    }
    obs = dec.frames["gnss_obs"].set_index("sat")
    assert obs.loc["G07", "signal"] == "C1C" and obs.loc["E11", "signal"] == "C1C"
    assert obs.loc["G07", "pseudorange_m"] == 21000000.125 and obs.loc["E11", "doppler_hz"] == 2500.25
    assert obs.loc["G07", "lli"] == 0  # locked 5 s, half cycle resolved
    assert obs.loc["E11", "lli"] == 3  # lock time 0 (new lock), half cycle unresolved
    assert (obs["receiver"] == "sample").all() and (obs["gnss_time_s"] == T0_GPS).all()
    msgs = _pyubx2(data / "sample.ubx")
    assert [m.identity for m in msgs] == ["NAV-PVT", "RXM-RAWX", "NAV-PVT"]  # pyubx2 drops the damaged frame too


def _galileo_row() -> dict[str, object]:
    r = nav_row("E11")
    week = T0_GPS // 604_800
    toe = (T0_GPS // 60 * 60) % 604_800
    r.update(
        IODE=77.0,
        SVclockBias=12345 * 2.0**-34,
        SVclockDrift=-7 * 2.0**-46,
        SVclockDriftRate=3 * 2.0**-59,
        Toe=toe,
        toc_gps_s=week * 604_800 + toe,
        TGD=np.nan,
        IODC=np.nan,
        FitIntvl=np.nan,
        BGDe5a=-9 * 2.0**-32,
        BGDe5b=-11 * 2.0**-32,
        DataSrc=513.0,
        SVacc=3.12,
        health=0.0,
        TransTime=(T0_GPS // 2 * 2 - 100) % 604_800,
        sqrtA=2_851_000_000 * 2.0**-19,
        Eccentricity=1_000_000 * 2.0**-33,
    )
    return r


def test_galileo_inav_round_trip(tmp_path: Path) -> None:
    from fieldlogs.recorders import inav

    assert inav._crc24q(int.from_bytes(b"123456789", "big"), 72) == 0xCDE703  # the CRC-24Q check value
    assert [inav.sisa_m(i) for i in (0, 49, 50, 75, 100, 125, 255)] == [0.0, 0.49, 0.5, 1.0, 2.0, 6.0, -1.0]
    gal = _galileo_row()
    p = tmp_path / "rx.ubx"
    write_ubx(
        p,
        gps=gps_frame(3),
        obs=obs_frame(3),
        nav=pd.DataFrame([gal, nav_row("G07")]),
        gnss={"nequick_ai": [60.75, 0.25, -0.125]},
    )
    assert [m.gnssId for m in _pyubx2(p) if m.identity == "RXM-SFRBX"].count(2) == 5  # pyubx2: 5 Galileo pages
    dec = read_ubx(p)
    got = dec.frames["gnss_nav"].set_index("sat").loc["E11"]
    for c in GNSS_NAV.column_names[1:]:
        want = gal[c]
        if isinstance(want, float) and np.isnan(want):
            assert np.isnan(got[c]), c
        else:
            assert got[c] == pytest.approx(want, rel=1e-15, abs=1e-25), c
    assert dec.gnss["nequick_ai"] == [60.75, 0.25, -0.125]


def test_galileo_page_with_a_bad_crc_is_not_decoded(tmp_path: Path) -> None:
    from fieldlogs.recorders import inav
    from fieldlogs.recorders.ubx_raw import _sfrbx

    pages = inav.encode(_galileo_row())
    damaged = list(pages[0])
    damaged[1] ^= 1 << 5  # a data bit of word type 1
    p = tmp_path / "rx.ubx"
    write_ubx(p, gps=gps_frame(2))
    p.write_bytes(p.read_bytes() + b"".join(_sfrbx(2, 11, w, 1) for w in [damaged, *pages[1:]]))
    dec = read_ubx(p)
    assert "gnss_nav" not in dec.frames  # word type 1 missing: no ephemeris
    assert dec.skipped["SFRBX Galileo pages not decoded (alert, CRC, word types 0, 6-10)"] == 1


def test_nav_dop_99_99_is_unknown(tmp_path: Path) -> None:
    """NAV-DOP hDOP 9999 (·0.01 = 99.99, what a u-blox receiver sends without a fix) → empty HDOP."""
    gps = gps_frame(3)
    gps["hdop"] = [0.9, 99.99, 99.9]
    p = tmp_path / "rx.ubx"
    write_ubx(p, gps=gps)
    assert [m.hDOP for m in _pyubx2(p) if m.identity == "NAV-DOP"] == pytest.approx([0.9, 99.99, 99.9])
    back = read_ubx(p).frames["gps"]["hdop"]
    assert back.iloc[0] == pytest.approx(0.9) and np.isnan(back.iloc[1]) and back.iloc[2] == pytest.approx(99.9)
