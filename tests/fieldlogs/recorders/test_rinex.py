"""RINEX readers against hand-made files, the writers read back by georinex and by the
readers, compressed files, and bad input."""

from __future__ import annotations

import gzip
import warnings
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from fieldlogs.recorders.rinex import read_rinex
from fieldlogs.recorders.rinex_nav import write_rinex_nav
from fieldlogs.recorders.rinex_obs import write_rinex_obs
from schemas.errors import InputError
from schemas.gnss import GNSS_NAV
from tests.fieldlogs.recorders.conftest import T0_GPS, nav_row, obs_frame


def georinex_load(path: Path) -> Any:
    import georinex

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its xarray.merge FutureWarnings
        return georinex.load(path)


def test_rinex_211_observations_by_hand(data: Path) -> None:
    dec = read_rinex(data / "sample_v211.obs")
    obs = dec.frames["gnss_obs"]
    t0 = (datetime(2026, 12, 1) - datetime(1980, 1, 6)).days * 86_400.0  # GPS time system
    assert obs["receiver"].unique().tolist() == ["RX211"]
    assert sorted(obs["gnss_time_s"].unique() - t0) == [0.0, 1.0]
    first = obs[obs["gnss_time_s"] == t0].set_index(["sat", "signal"])
    assert sorted(first.index) == [("G07", "C1C"), ("G07", "C2W"), ("G12", "C1C"), ("R05", "C1C"), ("R05", "C2P")]
    g07 = first.loc[("G07", "C1C")]
    assert (g07["pseudorange_m"], g07["carrier_cycles"], g07["doppler_hz"], g07["cn0_dbhz"], g07["lli"]) == (
        21000000.125,
        110355000.250,
        -1234.5,
        45.0,
        1,
    )
    assert first.loc[("G07", "C2W"), "pseudorange_m"] == 21000005.750  # P2, with L2 on its row
    assert first.loc[("G07", "C2W"), "carrier_cycles"] == 85990000.500
    assert first.loc[("R05", "C2P"), "carrier_cycles"] == 83125000.0
    assert dict(dec.skipped) == {"event records (epoch flags 2-6)": 1}
    # the same numbers through georinex
    ds = georinex_load(data / "sample_v211.obs")
    assert float(ds["C1"].sel(sv="G07").values[0]) == 21000000.125
    assert float(ds["L2"].sel(sv="R05").values[0]) == 83125000.0


def test_rinex_2_navigation_by_hand(data: Path) -> None:
    dec = read_rinex(data / "sample_v2.nav")
    nav = dec.frames["gnss_nav"].iloc[0]
    assert nav["sat"] == "G06"
    assert nav["toc_gps_s"] == 1025 * 604_800 + 409_904  # 1999-09-02 17:51:44 = Thursday, week 1025
    assert (nav["SVclockBias"], nav["IODE"], nav["Crs"], nav["sqrtA"]) == (
        -8.39701388031e-4,
        91.0,
        93.40625,
        5153.65489006,
    )
    assert (nav["Toe"], nav["week"], nav["TransTime"], nav["IODC"]) == (409_904.0, 1025.0, 406_800.0, 91.0)
    assert dec.gnss["klobuchar_alpha"] == [1.676e-08, 2.235e-08, -1.192e-07, -1.192e-07]
    assert dec.gnss["klobuchar_beta"] == [1.208e05, 1.310e05, -1.310e05, -1.966e05]
    assert dec.gnss["leap_seconds"] == 13
    assert dec.gnss["time_corrections"] == [
        {
            "type": "GPUT",
            "a0_s": 1.33179128170e-07,
            "a1_s_per_s": 1.07469588780e-13,
            "t_ref_s": 552960.0,
            "week": 1025.0,
        }
    ]
    ds = georinex_load(data / "sample_v2.nav")
    assert float(ds["sqrtA"].values.ravel()[0]) == nav["sqrtA"]


def test_obs_writer_round_trip(tmp_path: Path) -> None:
    obs = obs_frame(3)
    p = tmp_path / "rx1.obs"
    assert write_rinex_obs(obs, p) == 3
    back = read_rinex(p).frames["gnss_obs"]
    key = ["gnss_time_s", "sat", "signal"]
    a = obs.sort_values(key).reset_index(drop=True)
    b = back.sort_values(key).reset_index(drop=True)
    pd.testing.assert_frame_equal(a[[*key, "receiver"]], b[[*key, "receiver"]])
    for c in ("pseudorange_m", "carrier_cycles", "doppler_hz", "cn0_dbhz"):
        np.testing.assert_allclose(b[c], a[c], atol=5e-4, err_msg=c)  # F14.3
    assert b["lli"].tolist() == a["lli"].tolist()
    ds = georinex_load(p)
    g = a[(a["sat"] == "E11") & (a["signal"] == "C7Q")]
    np.testing.assert_allclose(ds["C7Q"].sel(sv="E11").values, g["pseudorange_m"], atol=5e-4)
    np.testing.assert_allclose(ds["L1C"].sel(sv="J02").values, a[a["sat"] == "J02"]["carrier_cycles"], atol=5e-4)
    assert (ds.time.values.astype("datetime64[s]").astype(np.int64) - 315_964_800 == g["gnss_time_s"]).all()


def test_nav_writer_round_trip(tmp_path: Path) -> None:
    rows = [
        nav_row("G07"),
        nav_row("J02"),
        {
            **nav_row("E11"),
            "TGD": np.nan,
            "IODC": np.nan,
            "FitIntvl": np.nan,
            "BGDe5a": -2.3e-9,
            "BGDe5b": -2.6e-9,
            "DataSrc": 517.0,
            "SVacc": 3.12,
        },
    ]
    glo: dict[str, Any] = dict.fromkeys(GNSS_NAV.column_names, np.nan)
    glo.update(
        sat="R05",
        toc_gps_s=T0_GPS + 900.0,
        SVclockBias=-1.2e-5,
        SVrelFreqBias=1e-12,
        MessageFrameTime=172_800.0,
        X=1.2e7,
        dX=1234.5,
        dX2=0.0,
        Y=-1.5e7,
        dY=-100.25,
        dY2=1e-6,
        Z=1.8e7,
        dZ=2000.0,
        dZ2=0.0,
        health=0.0,
        FreqNum=-3.0,
        AgeOpInfo=0.0,
    )
    nav = pd.DataFrame([*rows, glo])
    gnss = {
        "klobuchar_alpha": [1.1176e-08, 7.4506e-09, -5.9605e-08, -5.9605e-08],
        "nequick_ai": [25.25, 0.2344, 0.0064],
        "leap_seconds": 18,
        "time_corrections": [
            {"type": "GAGP", "a0_s": 1.5e-9, "a1_s_per_s": 2.0e-14, "t_ref_s": 432000.0, "week": 2447.0}
        ],
    }
    p = tmp_path / "nav.rnx"
    assert write_rinex_nav(nav, p, gnss) == 4
    dec = read_rinex(p)
    back = dec.frames["gnss_nav"].set_index("sat")
    for r in nav.to_dict("records"):
        got = back.loc[r["sat"]]
        for c in GNSS_NAV.column_names[1:]:
            want = r[c]
            if isinstance(want, float) and np.isnan(want):
                assert np.isnan(got[c]) or got[c] == 0.0, (r["sat"], c)
            else:
                assert got[c] == pytest.approx(want, rel=1e-12, abs=1e-20), (r["sat"], c)
    assert dec.gnss == gnss
    ds = georinex_load(p)
    assert float(ds["sqrtA"].sel(sv="G07").dropna("time").values[0]) == pytest.approx(
        nav_row("G07")["sqrtA"], rel=1e-12
    )
    assert float(ds["BGDe5a"].sel(sv="E11").dropna("time").values[0]) == -2.3e-9
    assert float(ds["X"].sel(sv="R05").dropna("time").values[0]) == 1.2e7  # georinex km → m


def test_gzip_and_hatanaka(tmp_path: Path) -> None:
    import hatanaka

    obs = obs_frame(2)
    p = tmp_path / "rx1.obs"
    write_rinex_obs(obs, p)
    plain = read_rinex(p).frames["gnss_obs"]
    gz = tmp_path / "rx1.obs.gz"
    gz.write_bytes(gzip.compress(p.read_bytes()))
    crx = tmp_path / "rx1.crx"
    crx.write_bytes(hatanaka.rnx2crx(p.read_bytes()))
    pd.testing.assert_frame_equal(read_rinex(gz).frames["gnss_obs"], plain)
    pd.testing.assert_frame_equal(read_rinex(crx).frames["gnss_obs"], plain)


def _damaged(tmp_path: Path, edit: Any) -> Path:
    p = tmp_path / "rx1.obs"
    write_rinex_obs(obs_frame(2), p)
    lines = p.read_text().splitlines()
    p.write_text("\n".join(edit(lines)) + "\n")
    return p


def _epoch_lines(lines: list[str]) -> list[int]:
    return [i for i, ln in enumerate(lines) if ln.startswith(">")]


@pytest.mark.parametrize(
    ("edit", "message", "line_of"),
    [
        (lambda ls: ls[: _epoch_lines(ls)[1] - 1] + ls[_epoch_lines(ls)[1] :], "announces 5 records but 4", 0),
        (
            lambda ls: [*ls[: _epoch_lines(ls)[1] + 1], "", *ls[_epoch_lines(ls)[1] + 2 :]],
            "blank satellite record",
            None,
        ),
        (lambda ls: [ln.replace("J02", "X02") for ln in ls], "unknown satellite system 'X'", None),
        (lambda ls: [ln for ln in ls if not ln.startswith("R ")], "system 'R' has no SYS", None),
        (lambda ls: [ln.replace("> 2026 12 01 10 00", ">          10 00") for ln in ls], "blank or malformed epoch", 0),
        (lambda ls: ls[: _epoch_lines(ls)[0]], "no epoch records", None),
    ],
)
def test_bad_observation_files(tmp_path: Path, edit: Any, message: str, line_of: int | None) -> None:
    p = _damaged(tmp_path, edit)
    with pytest.raises(InputError, match=message) as exc:
        read_rinex(p)
    assert exc.value.path == str(p)
    if line_of is not None:
        lines = p.read_text().splitlines()
        assert exc.value.row == _epoch_lines(lines)[line_of] + 1


def test_not_rinex(tmp_path: Path) -> None:
    p = tmp_path / "x.rnx"
    p.write_text("hello\n")
    with pytest.raises(InputError, match="not a RINEX file"):
        read_rinex(p)


def _d19(*values: float) -> str:
    return "".join(f"{v:19.12E}".replace("E", "D") for v in values)


def test_rinex_2_glonass_navigation_by_hand(tmp_path: Path) -> None:
    head = [
        f"{'     2.11           G: GLONASS NAV DATA':<60}RINEX VERSION / TYPE",
        f"{'':<60}END OF HEADER",
    ]
    rec = [
        " 5 26 12  1 10 15  0.0" + _d19(-1.2e-5, 1.0e-12, 172800.0),
        "   " + _d19(12000.0, 1.2345, 0.0, 0.0),  # X [km], dX [km/s], dX2, health
        "   " + _d19(-15000.0, -0.1, 1.0e-9, -3.0),  # Y, dY, dY2, frequency number
        "   " + _d19(18000.0, 2.0, 0.0, 0.0),  # Z, dZ, dZ2, age
    ]
    p = tmp_path / "glo.26g"
    p.write_text("\n".join(head + rec) + "\n")
    nav = read_rinex(p).frames["gnss_nav"].iloc[0]
    assert nav["sat"] == "R05"
    utc = (datetime(2026, 12, 1) - datetime(1980, 1, 6)).days * 86_400.0 + 10 * 3600 + 15 * 60
    assert nav["toc_gps_s"] == utc + 18.0  # GLONASS epochs are UTC
    assert (nav["X"], nav["dX"], nav["Y"], nav["FreqNum"], nav["Z"]) == (1.2e7, 1234.5, -1.5e7, -3.0, 1.8e7)
    assert (nav["SVclockBias"], nav["SVrelFreqBias"], nav["MessageFrameTime"]) == (-1.2e-5, 1.0e-12, 172800.0)
    assert np.isnan(nav["sqrtA"])


def test_navigation_record_of_an_unknown_system(tmp_path: Path) -> None:
    p = tmp_path / "nav.rnx"
    write_rinex_nav(pd.DataFrame([nav_row("G07")]), p)
    text = p.read_text().replace("\nG07 ", "\nX07 ")
    p.write_text(text)
    with pytest.raises(InputError, match="unknown satellite system 'X'") as exc:
        read_rinex(p)
    assert exc.value.row == text.splitlines().index(next(ln for ln in text.splitlines() if ln.startswith("X07"))) + 1


def _v211(data: Path, tmp_path: Path, edit: Any) -> Path:
    """The hand-made RINEX 2.11 file, edited (header: lines 1-7; epoch records on 8, 15 (an event), 17)."""
    p = tmp_path / "rx.obs"
    p.write_text("\n".join(edit((data / "sample_v211.obs").read_text().split("\n"))))
    return p


@pytest.mark.parametrize(
    ("edit", "message", "row"),
    [
        # the first epoch's G07 record (2 lines) is missing: the event record then on line 13 would be data
        (lambda ls: ls[:8] + ls[10:], "announces 3 satellites but has fewer records: the epoch record on line 13", 8),
        (lambda ls: [ln.replace("3G07G12R05", "3G07G12X05") for ln in ls], "unknown satellite system 'X'", 8),
        (lambda ls: [ln.replace("3G07G12R05", "3G07G12   ") for ln in ls], "announces 3 satellites but lists 2", 8),
        (lambda ls: [ln.replace(" 26 12  1  0  0  0.0", " 26 13  1  0  0  0.0") for ln in ls], "out of range", 8),
        (lambda ls: [ln.replace(" 26 12  1  0  0  0.0", "                    ") for ln in ls], "malformed epoch", 8),
        (lambda ls: [*ls[:14], "", *ls[14:]], "blank line where an epoch record was expected", 15),
        (lambda ls: ls[:-3], "announces 2 satellites but the file ends", 17),
        (lambda ls: [*ls[:7], "  21000000.125", *ls[7:]], "no epoch flag and count", 8),
    ],
)
def test_bad_rinex_211_observation_files(data: Path, tmp_path: Path, edit: Any, message: str, row: int) -> None:
    p = _v211(data, tmp_path, edit)
    with pytest.raises(InputError, match=message) as exc:
        read_rinex(p)
    assert (exc.value.path, exc.value.row) == (str(p), row)
