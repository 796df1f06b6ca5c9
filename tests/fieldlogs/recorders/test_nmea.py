"""NMEA reader against a hand-made file, bad input, and the writer read back by pynmea2."""

from __future__ import annotations

from datetime import datetime
from functools import reduce
from pathlib import Path

import numpy as np
import pandas as pd
import pynmea2
import pytest

from fieldlogs.recorders.nmea import KNOT_MPS, read_nmea, write_nmea
from schemas.errors import InputError
from tests.fieldlogs.recorders.conftest import gps_frame


def sentence(body: str) -> str:
    return f"${body}*{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def test_hand_made_file(data: Path) -> None:
    dec = read_nmea(data / "sample.nmea")
    gps = dec.frames["gps"]
    assert len(gps) == 3  # 23:59:59, then midnight: 00:00:00 (its RMC is bad) and 00:00:01
    day = (datetime(2026, 12, 14) - datetime(1980, 1, 6)).days * 86_400.0
    np.testing.assert_allclose(gps["gnss_time_s"], day + np.array([86_399.0, 86_400.0, 86_401.0]) + 18.0)
    assert gps["lat"].iloc[0] == pytest.approx(35 + 54.42310 / 60, abs=1e-12)
    assert gps["lon"].iloc[0] == pytest.approx(139 + 28.98580 / 60, abs=1e-12)
    assert gps["fix"].tolist() == [2, 1, 0]  # GGA 2 (DGPS), 1, 0 (GGA takes precedence over RMC)
    assert gps["nsat"].tolist() == [12, 8, 0]
    assert gps["hdop"].tolist()[:2] == [0.8, 1.1]
    assert np.isnan(gps["hdop"].iloc[2])  # GGA's 99.99 without a fix: "unknown", not a DOP
    assert gps["height_m"].iloc[0] == pytest.approx(25.0 + 38.5)  # altitude + geoid separation
    assert gps["speed_mps"].iloc[0] == pytest.approx(10.0 * 1852 / 3600)
    assert gps[["sigma_lat_m", "sigma_lon_m", "sigma_height_m"]].iloc[0].tolist() == [0.45, 0.35, 0.90]
    # third epoch: no GGA position, the valid RMC gives it
    assert gps["lat"].iloc[2] == pytest.approx(35 + 54.42350 / 60, abs=1e-12)
    assert gps["lat"].iloc[1] == pytest.approx(35 + 54.42330 / 60, abs=1e-12)  # its GGA (RMC bad)
    assert dict(dec.skipped) == {
        "bad checksum": 1,
        "sentence GPGSV not imported": 1,
        "sentence PUBX not imported": 1,
    }
    assert dec.records == 12


def test_gsa_fills_nsat_and_hdop_without_gga(tmp_path: Path) -> None:
    lines = [
        sentence("GNRMC,101010.00,A,3554.00000,N,13924.00000,E,0.0,0.0,011226,,,A"),
        sentence("GPGSA,A,3,05,07,13,,,,,,,,,,1.50,0.90,1.20,1"),
        sentence("GLGSA,A,3,70,71,,,,,,,,,,,1.50,0.90,1.20,2"),
    ]
    p = tmp_path / "a.nmea"
    p.write_text("\n".join(lines) + "\n")
    gps = read_nmea(p).frames["gps"]
    assert gps["nsat"].tolist() == [5]
    assert gps["hdop"].tolist() == [0.9]
    assert gps["fix"].tolist() == [1]


@pytest.mark.parametrize(
    ("lines", "message", "line"),
    [
        (
            [
                sentence("GNRMC,101011.00,A,3554.0,N,13924.0,E,0,0,011226,,,A"),
                sentence("GNGGA,101011.00,3554.0,N,13924.0,E,1,08,1.0,1.0,M,0.0,M,,"),
                sentence("GNGGA,101010.00,3554.0,N,13924.0,E,1,08,1.0,1.0,M,0.0,M,,"),
            ],
            "out of order",
            3,
        ),
        (
            [
                sentence("GNRMC,101010.00,A,3554.0,N,13924.0,E,0,0,011226,,,A"),
                sentence("GPGGA,101010.00,3554.0,N,13924.0,E,1,08,1.0,1.0,M,0.0,M,,"),
                sentence("GNGGA,101010.00,3554.1,N,13924.0,E,1,08,1.0,1.0,M,0.0,M,,"),
            ],
            "mixed talkers: GN/GPGGA",
            3,
        ),
        ([sentence("GNGGA,101010.00,3554.0,N,13924.0,E,1,08,1.0,1.0,M,0.0,M,,")], "no RMC sentence", None),
        (["$GNGGA,101010.00,3554.0,N,13924.0,E,1,08,1.0,1.0,M,0.0,M,,*00"], "no GGA, RMC or GST", None),
    ],
)
def test_bad_input_names_file_and_line(tmp_path: Path, lines: list[str], message: str, line: int | None) -> None:
    p = tmp_path / "bad.nmea"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=message) as exc:
        read_nmea(p)
    assert exc.value.path == str(p)
    assert exc.value.row == line


def test_writer_read_back_by_pynmea2_and_the_reader(tmp_path: Path) -> None:
    gps = gps_frame(5)
    p = tmp_path / "w.nmea"
    n = write_nmea(gps, p)
    lines = p.read_text().splitlines()
    assert n == len(lines) == 5 * 5
    parsed = [pynmea2.parse(x, check=True) for x in lines]
    gga = [m for m in parsed if m.sentence_type == "GGA"]
    rmc = [m for m in parsed if m.sentence_type == "RMC"]
    gst = [m for m in parsed if m.sentence_type == "GST"]
    for i, m in enumerate(gga):
        assert m.latitude == pytest.approx(gps["lat"].iloc[i], abs=1e-7)  # 1e-6 minute resolution
        assert m.longitude == pytest.approx(gps["lon"].iloc[i], abs=1e-7)
        assert int(m.gps_qual) == gps["fix"].iloc[i]
        assert int(m.num_sats) == gps["nsat"].iloc[i]
        assert float(m.horizontal_dil) == pytest.approx(gps["hdop"].iloc[i], abs=0.005)
        assert float(gst[i].std_dev_latitude) == 0.5
        assert float(rmc[i].spd_over_grnd) * KNOT_MPS == pytest.approx(gps["speed_mps"].iloc[i], abs=3e-4)
    back = read_nmea(p).frames["gps"]
    for c in (
        "gnss_time_s",
        "lat",
        "lon",
        "fix",
        "nsat",
        "hdop",
        "height_m",
        "speed_mps",
        "course_deg",
        "sigma_lat_m",
        "sigma_height_m",
    ):
        np.testing.assert_allclose(back[c].to_numpy(dtype=float), gps[c].to_numpy(dtype=float), atol=3e-4, err_msg=c)


def test_crlf_and_gzip(tmp_path: Path, data: Path) -> None:
    import gzip

    raw = (data / "sample.nmea").read_bytes()
    assert b"\r\n" in raw
    gz = tmp_path / "sample.nmea.gz"
    gz.write_bytes(gzip.compress(raw))
    a, b = read_nmea(data / "sample.nmea").frames["gps"], read_nmea(gz).frames["gps"]
    pd.testing.assert_frame_equal(a, b)


def test_unknown_dop_is_empty_and_the_import_passes_check(data: Path, tmp_path: Path) -> None:
    """Receivers write HDOP 99.99 for "unknown" (u-blox without a fix); the gps stream's HDOP
    is at most 99.9 (schemas/logs.py), so the reader leaves it empty and `logs check` of the
    imported file reports nothing about the gps stream."""
    import json

    from typer.testing import CliRunner

    from cli.main import app

    p = tmp_path / "a.nmea"
    p.write_text(
        "\n".join(
            [
                sentence("GNRMC,101010.00,V,,,,,,,011226,,,N"),
                sentence("GNGGA,101010.00,,,,,0,00,99.99,,,,,,"),
                sentence("GNGSA,A,1,,,,,,,,,,,,,99.99,99.99,99.99,1"),
                sentence("GNGGA,101011.00,3554.00000,N,13924.00000,E,1,07,99.90,25.0,M,38.5,M,,"),
            ]
        )
        + "\n"
    )
    gps = read_nmea(p).frames["gps"]
    assert np.isnan(gps["hdop"].iloc[0]) and gps["hdop"].iloc[1] == 99.9
    out = tmp_path / "run"
    res = CliRunner().invoke(
        app, ["logs", "import", str(p), "--vehicle", str(data / "vehicle.toml"), "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["logs", "check", str(out), "--format", "json"])
    findings = json.loads(res.output)["runs"][0]["findings"]
    assert {f["rule"] for f in findings} == {"log.missing_stream"}  # imu and tacho; nothing on gps
