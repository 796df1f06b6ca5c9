"""``trainpos logs import`` end to end: simulated recorders (NMEA, a drifting IMU logger,
a tacho CSV on Unix time) → one run that ``logs check``, ``run`` and ``audit`` accept;
bad input with its documented exit code and nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner, Result

from cli.main import app
from fieldlogs.recorders.export import write_recorder_files
from fieldlogs.recorders.timebase import UNIX_TO_GPS_S, iso_to_gps
from fieldlogs.recorders.ubx import write_ubx
from fieldlogs.runs.handle import Run
from tests.fieldlogs.audit.audit_data import AuditData, audit_data
from tests.fieldlogs.recorders.conftest import gps_frame, obs_frame

G = 9.80665
DRIFT = 0.004  # the IMU logger runs 0.4 % fast


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def sim(tmp_path_factory: pytest.TempPathFactory) -> AuditData:
    return audit_data(tmp_path_factory)


def _vehicle(path: Path, run: Run, receiver: str = "gnss") -> Path:
    path.write_text(
        f'vehicle_id = "{run.meta.vehicle_id}"\nvehicle_kind = "train"\nlength_m = 20.0\nreference = "centre"\n'  # type: ignore[union-attr]
        f'front_x_m = 10.0\ntacho_axle = "A1"\n[[antennas]]\nid = "a1"\nreceiver = "{receiver}"\nx_m = 7.0\n'
        f'y_m = 0.0\nz_m = 3.8\n[[axles]]\nid = "A1"\nx_m = 8.5\n'
        f"wheel_diameter_m = {run.meta.wheel_diameter_m}\nteeth = {run.meta.teeth}\n",  # type: ignore[union-attr]
        encoding="utf-8",
    )
    return path


def _recorders(src: Path, dst: Path) -> dict[str, Path]:
    """The simulated run as three recorders would have logged it."""
    dst.mkdir()
    run = Run(src)
    start = iso_to_gps(run.meta.start_time)  # type: ignore[union-attr]
    imu, tacho = run.stream("imu"), run.stream("tacho")
    assert imu is not None and tacho is not None
    tau_ms = (imu["t"].to_numpy() + 3.0) * (1.0 + DRIFT) * 1000.0
    pairs = np.where(np.arange(len(imu)) % 100 == 0, start + imu["t"].to_numpy(), np.nan)
    pd.DataFrame(
        {
            "ts": np.round(tau_ms, 3),
            "pps_gps": pairs,
            "AccX": imu["ax"] / G,
            "AccY": -imu["ay"] / G,  # sensor y right
            "AccZ": -imu["az"] / G,  # sensor z down
            "GyrX": np.degrees(imu["wx"]),
            "GyrY": -np.degrees(imu["wy"]),
            "GyrZ": -np.degrees(imu["wz"]),
        }
    ).to_csv(dst / "imu.csv", index=False)
    unix = start - 18.0 + UNIX_TO_GPS_S + tacho["t"].to_numpy()  # UTC = GPS − 18 s in 2026
    pd.DataFrame({"unix": unix, "count": tacho["pulses"]}).to_csv(dst / "tacho.csv", index=False)
    (dst / "imu.toml").write_text(
        'stream = "imu"\n[time]\ncolumn = "ts"\nunit = "ms"\nbase = "relative"\ngnss_column = "pps_gps"\n'
        '[columns]\nax = "AccX"\nay = "AccY"\naz = "AccZ"\nwx = "GyrX"\nwy = "GyrY"\nwz = "GyrZ"\n'
        '[units]\nax = "g"\nay = "g"\naz = "g"\nwx = "deg/s"\nwy = "deg/s"\nwz = "deg/s"\n'
        '[axes]\nx = "+x"\ny = "-y"\nz = "-z"\n',
        encoding="utf-8",
    )
    (dst / "tacho.toml").write_text(
        'stream = "tacho"\n[time]\ncolumn = "unix"\nbase = "unix"\n[columns]\npulses = "count"\n', encoding="utf-8"
    )
    [nmea] = write_recorder_files(src, "nmea")
    return {
        "nmea": nmea,
        "imu": dst / "imu.csv",
        "tacho": dst / "tacho.csv",
        "imu_map": dst / "imu.toml",
        "tacho_map": dst / "tacho.toml",
        "vehicle": _vehicle(dst / "car.toml", run),
    }


@pytest.fixture(scope="module")
def imported(sim: AuditData, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, dict[str, Path]]:
    root = tmp_path_factory.mktemp("import")
    src = root / "sim"
    import shutil

    shutil.copytree(sim.runs[0], src)
    files = _recorders(src, root / "rec")
    out = root / "logs" / "imported"
    res = invoke(
        "logs",
        "import",
        files["nmea"],
        files["imu"],
        files["tacho"],
        "--mapping",
        files["imu_map"],
        "--mapping",
        files["tacho_map"],
        "--vehicle",
        files["vehicle"],
        "--out",
        out,
        "--run-id",
        "IMP-1",
    )
    assert res.exit_code == 0, res.output
    assert "drift 4000" in res.output.replace(",", "")  # the logger's clock, in ppm
    return src, out, files


def test_imported_run_matches_the_recorded_one(imported: tuple[Path, Path, dict[str, Path]]) -> None:
    src, out, _ = imported
    a, b = Run(src), Run(out)
    assert b.meta is not None and a.meta is not None
    assert b.meta.run_id == "IMP-1" and b.meta.teeth == a.meta.teeth
    assert iso_to_gps(b.meta.start_time) == pytest.approx(iso_to_gps(a.meta.start_time), abs=1e-3)
    ia, ib = a.stream("imu"), b.stream("imu")
    assert ia is not None and ib is not None and len(ia) == len(ib)
    np.testing.assert_allclose(ib["t"], ia["t"], atol=1e-3)  # drift removed
    np.testing.assert_allclose(ib[["ax", "ay", "az"]], ia[["ax", "ay", "az"]], atol=1e-9)
    np.testing.assert_allclose(ib[["wx", "wy", "wz"]], ia[["wx", "wy", "wz"]], atol=1e-9)
    ta, tb = a.stream("tacho"), b.stream("tacho")
    assert ta is not None and tb is not None
    np.testing.assert_allclose(tb["t"], ta["t"], atol=1e-5)
    assert tb["pulses"].tolist() == ta["pulses"].tolist()
    ga, gb = a.stream("gps"), b.stream("gps")
    assert ga is not None and gb is not None
    np.testing.assert_allclose(gb["lat"], ga["lat"], atol=2e-8)
    assert gb["fix"].tolist() == ga["fix"].tolist()
    raw = json.loads((out / "run.json").read_text())
    assert [s["format"] for s in raw["sources"]] == ["nmea", "csv", "csv"]
    assert all(len(s["sha256"]) == 64 for s in raw["sources"])
    clock = raw["sources"][1]["clock"]
    assert clock["drift"] == pytest.approx(DRIFT, abs=1e-7) and clock["residual_max_s"] < 1e-4
    assert raw["vehicle"]["antennas"][0]["receiver"] == "gnss"


def test_check_run_and_audit_accept_it(
    imported: tuple[Path, Path, dict[str, Path]], sim: AuditData, tmp_path: Path
) -> None:
    src, out, _ = imported
    res = invoke("logs", "check", out, "--format", "json")
    assert res.exit_code == 0, res.output
    res = invoke("run", out, "--db", sim.db, "--out", tmp_path / "pos")
    assert res.exit_code == 0, res.output
    assert invoke("run", src, "--db", sim.db, "--out", tmp_path / "pos-src").exit_code == 0
    summary = json.loads((tmp_path / "pos" / "summary.json").read_text())
    original = json.loads((tmp_path / "pos-src" / "summary.json").read_text())
    assert summary["duration_s"] == pytest.approx(original["duration_s"], abs=0.2)
    assert summary["distance_m"] == pytest.approx(original["distance_m"], rel=1e-3)
    res = invoke("audit", out.parent, "--db", sim.db, "--out", tmp_path / "a.sqlite", "--workers", "1")
    assert res.exit_code == 0, res.output
    res = invoke("logs", "info", out)
    assert res.exit_code == 0 and "IMP-1" in res.output


def _refused(res: Result, code: int, out: Path, *needles: str) -> None:
    assert res.exit_code == code, res.output
    assert "Traceback" not in res.output
    for n in needles:
        assert n in " ".join(res.output.split()), (n, res.output)
    assert not out.exists()


def test_bad_input_exit_codes_and_nothing_written(imported: tuple[Path, Path, dict[str, Path]], tmp_path: Path) -> None:
    _, done, f = imported
    out = tmp_path / "new"
    # the output exists: 3
    res = invoke("logs", "import", f["nmea"], "--vehicle", f["vehicle"], "--out", done)
    assert res.exit_code == 3 and "--force" in res.output
    # no vehicle: 2
    _refused(invoke("logs", "import", f["nmea"], "--out", out), 2, out, "--vehicle")
    # a mapping naming a column that is not there: 2, file and column named
    bad_map = tmp_path / "bad.toml"
    bad_map.write_text(f["imu_map"].read_text().replace('ax = "AccX"', 'ax = "AccelX"'))
    _refused(
        invoke("logs", "import", f["imu"], "--mapping", bad_map, "--vehicle", f["vehicle"], "--out", out),
        2,
        out,
        str(f["imu"]),
        "'AccelX'",
        "did you mean 'AccX'",
    )
    # an IMU in g declared as m/s²: 1, detected from the data
    g_map = tmp_path / "g.toml"
    g_map.write_text(f["imu_map"].read_text().replace('ax = "g"\nay = "g"\naz = "g"\n', ""))
    _refused(
        invoke("logs", "import", f["imu"], "--mapping", g_map, "--vehicle", f["vehicle"], "--out", out),
        1,
        out,
        "look like g",
    )
    # a truncated UBX file: 2
    ubx = tmp_path / "gnss.ubx"
    write_ubx(ubx, gps=gps_frame(5), obs=obs_frame(5, receiver="gnss"))
    cut = tmp_path / "cut.ubx"
    cut.write_bytes(ubx.read_bytes()[:-40])
    _refused(invoke("logs", "import", cut, "--vehicle", f["vehicle"], "--out", out), 2, out, "truncated UBX")
    # a receiver without an antenna: 1
    other = tmp_path / "rover.ubx"
    write_ubx(other, gps=gps_frame(5), obs=obs_frame(5, receiver="rover"))
    _refused(
        invoke("logs", "import", other, "--vehicle", f["vehicle"], "--out", out),
        1,
        out,
        "receiver(s) rover have no antenna",
    )
    # two sources of one stream: 2; a table source without its mapping: 2
    _refused(
        invoke("logs", "import", f["nmea"], f["nmea"], "--vehicle", f["vehicle"], "--out", out),
        2,
        out,
        "two sources give the 'gps' stream",
    )
    _refused(
        invoke("logs", "import", f["imu"], "--vehicle", f["vehicle"], "--out", out),
        2,
        out,
        "1 CSV/Parquet source(s) but 0 --mapping",
    )


def test_ubx_import_with_raw_observations(imported: tuple[Path, Path, dict[str, Path]], tmp_path: Path) -> None:
    _, _, f = imported
    ubx = tmp_path / "gnss.ubx"
    write_ubx(ubx, gps=gps_frame(10), obs=obs_frame(10, receiver="gnss"))
    out = tmp_path / "u"
    res = invoke("logs", "import", ubx, "--vehicle", f["vehicle"], "--out", out)
    assert res.exit_code == 0, res.output
    run = Run(out)
    obs = run.stream("gnss_obs")
    assert obs is not None and len(obs) == 70 and (obs["receiver"] == "gnss").all()
    np.testing.assert_allclose(obs["gnss_time_s"] - obs["t"], obs["gnss_time_s"].min())
    res = invoke("logs", "check", out, "--format", "json")
    rules = {f["rule"] for f in json.loads(res.output)["runs"][0]["findings"]}
    assert rules == {"log.missing_stream"}  # a train without imu and tacho: reported, not refused


def test_simulate_writes_the_gnss_part_as_a_recorder(sim: AuditData, tmp_path: Path) -> None:
    out = tmp_path / "sim-ubx"
    res = invoke("simulate", "--db", sim.db, "--out", out, "--seed", "5", "--format", "ubx")
    assert res.exit_code == 0, res.output
    ubx = out / "recorder" / "gnss.ubx"
    assert ubx.is_file()
    assert "log.unknown_file" not in {f.rule for f in Run(out).findings}  # recorder/ is a known extra
    gps = Run(out).stream("gps")
    assert gps is not None
    from fieldlogs.recorders.ubx import read_ubx

    back = read_ubx(ubx).frames["gps"]
    assert len(back) == len(gps)
    np.testing.assert_allclose(back["lat"], gps["lat"], atol=1e-9)  # NaN where there is no fix, both sides
    assert back["fix"].tolist() == gps["fix"].tolist()
    # a run without raw observations cannot be written as RINEX: refused, nothing left behind
    # (``simulate --format rinex`` switches [gnss_raw] on: tests/fieldlogs/gnss/test_roundtrip.py)
    from schemas.errors import UsageError

    with pytest.raises(UsageError, match="gnss_obs"):
        write_recorder_files(out, "rinex", force=True)
    assert (out / "recorder" / "gnss.ubx").is_file() and not (out / "recorder" / "nav.rnx").exists()


def test_a_road_rail_vehicle_without_a_tachometer(tmp_path: Path) -> None:
    """A vehicle without tacho axle (optional for a road-rail vehicle without a tacho stream,
    README) is imported without a wheel; a train without one is refused (exit 1)."""
    from tests.fieldlogs.recorders.conftest import DATA

    veh = tmp_path / "rr.toml"
    veh.write_text(
        'vehicle_id = "RR1"\nvehicle_kind = "road_rail"\nlength_m = 8.0\nreference = "centre"\nfront_x_m = 4.0\n'
        '[[antennas]]\nid = "roof"\nreceiver = "RX211"\nx_m = 0.0\ny_m = 0.0\nz_m = 3.0\n'
    )
    out = tmp_path / "run"
    res = invoke("logs", "import", DATA / "sample_v211.obs", DATA / "sample_v2.nav", "--vehicle", veh, "--out", out)
    assert res.exit_code == 0, res.output
    meta = json.loads((out / "run.json").read_text())
    assert meta["vehicle_kind"] == "road_rail" and meta.get("wheel_diameter_m") is None and meta.get("teeth") is None
    assert Run(out).stream("gnss_obs") is not None
    veh.write_text(veh.read_text().replace('"road_rail"', '"train"'))
    _refused(
        invoke("logs", "import", DATA / "sample_v211.obs", "--vehicle", veh, "--out", tmp_path / "t"),
        1,
        tmp_path / "t",
        "'tacho_axle' is missing",
    )
