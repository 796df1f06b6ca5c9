"""Simulated run → recorder files → ``logs import`` → the same GNSS solutions [S002].

RINEX keeps everything the solver uses to the millimetre (F14.3 pseudoranges and carrier,
D19.12 ephemerides, 0.1 µs epochs), so the solutions of the imported run equal those of the
run's own streams; UBX rounds C/N0 to whole dB-Hz and re-encodes the ephemerides in the
navigation message's units, so its solutions are close, not equal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.gnss.gis import gis_track
from fieldlogs.gnss.report import position_report
from fieldlogs.gnss.runinputs import run_gnss
from fieldlogs.recorders.export import write_recorder_files
from fieldlogs.recorders.importer import import_run
from fieldlogs.runs.handle import read_run
from tests.fieldlogs.gnss.runs import simulate_gnss_run


@pytest.fixture(scope="module")
def network(sample_db: Path) -> Network:
    return read_network(sample_db)


@pytest.fixture(scope="module")
def run_dir(network: Network, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulate_gnss_run(network, tmp_path_factory.mktemp("rt") / "run", seed=21, length_m=2500.0)


def _epochs(folder: Path, network: Network) -> pd.DataFrame:
    run = read_run(folder)
    g = run_gnss(run)
    assert g is not None
    rep = position_report(run.run_id, g, gis_track(network, "0420", "D"), 1)
    e = rep.epochs.copy()
    e["key"] = e["receiver"] + "@" + e["gnss_time_s"].round(4).astype(str)
    return e.set_index("key")


def test_rinex_round_trip_gives_the_same_solutions(run_dir: Path, network: Network, tmp_path: Path) -> None:
    files = write_recorder_files(run_dir, "rinex", force=True)
    assert sorted(f.name for f in files) == ["nav.rnx", "rx1.obs", "rx2.obs", "vehicle.toml"]
    out = tmp_path / "imported"
    vehicle = next(f for f in files if f.name == "vehicle.toml")
    import_run([f for f in files if f.suffix != ".toml"], out, vehicle=vehicle)
    a, b = _epochs(run_dir, network), _epochs(out, network)
    assert len(a) == len(b) and set(a.index) == set(b.index)
    b = b.loc[a.index]
    assert (a["status"] == b["status"]).all() and (a["available"] == b["available"]).all()
    assert (a["used"].map(tuple) == b["used"].map(tuple)).all()
    np.testing.assert_allclose(b["km_m"], a["km_m"], atol=0.005)
    np.testing.assert_allclose(b["uncertainty_m"], a["uncertainty_m"], rtol=1e-4)
    np.testing.assert_allclose(b["lsq_km_m"], a["lsq_km_m"], atol=0.005)


def test_ubx_round_trip_one_file_per_receiver(run_dir: Path, network: Network, tmp_path: Path) -> None:
    files = write_recorder_files(run_dir, "ubx", force=True)
    assert sorted(f.name for f in files) == ["gnss.ubx", "rx1.ubx", "rx2.ubx", "vehicle.toml"]
    out = tmp_path / "imported"
    vehicle = next(f for f in files if f.name == "vehicle.toml")
    import_run([f for f in files if f.name.startswith("rx")], out, vehicle=vehicle)
    a, b = _epochs(run_dir, network), _epochs(out, network)
    common = a.index.intersection(b.index)
    assert len(common) == len(a)
    ok = a.loc[common, "available"] & b.loc[common, "available"]
    assert ok.mean() > 0.95
    diff = (a.loc[common, "km_m"] - b.loc[common, "km_m"])[ok].abs()
    assert diff.median() < 2.0 and (diff <= a.loc[common, "uncertainty_m"][ok]).all()


def test_ubx_export_writes_gnss_sbas_as_sfrbx_read_back_identically(network: Network, tmp_path: Path) -> None:
    from pyubx2 import UBXReader

    from fieldlogs.gnss.sbas import SbasCorrections
    from fieldlogs.recorders.ubx import read_ubx

    run_dir = simulate_gnss_run(network, tmp_path / "run", seed=8, length_m=1500.0, gnss_raw={"sbas": True})
    sb = read_run(run_dir).stream("gnss_sbas")
    assert sb is not None and len(sb) > 100
    files = write_recorder_files(run_dir, "ubx", force=True)
    first = next(f for f in files if f.name == "rx1.ubx")
    with first.open("rb") as fh:
        sfrbx = [m for _, m in UBXReader(fh, protfilter=2) if m.identity == "RXM-SFRBX" and m.gnssId == 1]
    words = ["".join(f"{getattr(m, f'dwrd_{k:02d}'):08X}" for k in range(1, 9)) for m in sfrbx]
    dec = read_ubx(first)
    back = dec.frames["gnss_sbas"]
    late = sum(v for k, v in dec.skipped.items() if "after the last RXM-RAWX" in k)
    n = len(back)
    assert n + late == len(sb) and late <= 2  # at most the messages after the run's last epoch
    assert [m.svId for m in sfrbx] == sb["prn"].tolist()
    assert words == sb["message_hex"].tolist()  # pyubx2 reads the 250 bits we wrote
    assert back["message_hex"].tolist() == sb["message_hex"].iloc[:n].tolist()
    assert back["prn"].tolist() == sb["prn"].iloc[:n].tolist()
    assert back["msg_type"].tolist() == sb["msg_type"].iloc[:n].tolist()
    lag = back["gnss_time_s"].to_numpy() - sb["gnss_time_s"].to_numpy()[:n]
    assert (lag >= -1e-6).all() and (lag <= 1.0 + 1e-6).all()  # the next epoch: reception bounded above
    a, b = SbasCorrections.from_stream(sb.iloc[:n]).messages, SbasCorrections.from_stream(back).messages
    for name in ("fast", "integrity"):
        np.testing.assert_array_equal(getattr(a, name)["t_of"], getattr(b, name)["t_of"])
    assert not any(f.name == "rx2.ubx" and "gnss_sbas" in read_ubx(f).frames for f in files)
    out = tmp_path / "imported"
    vehicle = next(f for f in files if f.name == "vehicle.toml")
    import_run([f for f in files if f.name.startswith("rx")], out, vehicle=vehicle)
    imported = read_run(out).stream("gnss_sbas")
    assert imported is not None and imported["message_hex"].tolist() == back["message_hex"].tolist()
