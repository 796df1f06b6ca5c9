"""Real receiver files (tests/data/rinex/README.md): a Trimble rover's RINEX 2.11 and a Trimble
NetR9 reference station's RINEX 3.04, each with its broadcast navigation file, imported with
``logs import`` and positioned. The unconstrained solution lands within tens of metres of the
header's APPROX POSITION XYZ (+ the antenna height, ANTENNA: DELTA H); the track-constrained
one, on a synthetic straight 4 km track laid through that position, within a few metres of it
and inside its stated uncertainty."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fieldlogs.gnss.geodesy import ecef_to_geodetic, enu_basis
from fieldlogs.gnss.gis import GisTrack
from fieldlogs.gnss.report import position_report
from fieldlogs.gnss.runinputs import run_gnss
from fieldlogs.gnss.track import TrackLine
from fieldlogs.recorders.importer import import_run
from fieldlogs.runs.handle import read_run

DATA = Path(__file__).resolve().parents[2] / "data" / "rinex"

#: file stem → (observation file, navigation file, receiver name, APPROX POSITION XYZ, DELTA H)
CASES = {
    "trimble-rinex211": (
        "14601736.18o", "14601736.18n", "st", (-4647137.5830, 2562189.6255, -3526626.7006), 2.0,
    ),
    "netr9-rinex304": (
        "OPEC00NOR_S_20220010000_01D_30S_MO_excerpt.rnx", "OPEC00NOR_S_20220010000_01D_GN_excerpt.rnx",
        "OPEC00NOR_S_20220010000_01D_30S_MO_excerpt", (3149785.9652, 598260.8822, 5495348.4927), 0.0,
    ),
}  # fmt: skip


def _vehicle(path: Path, receiver: str, height_m: float) -> Path:
    path.write_text(
        'vehicle_id = "STATION"\nvehicle_kind = "train"\nlength_m = 2.0\nreference = "the marker"\n'
        'front_x_m = 1.0\ntacho_axle = "A1"\n[[antennas]]\nid = "antenna"\n'
        f'receiver = "{receiver}"\nx_m = 0.0\ny_m = 0.0\nz_m = {height_m}\n'
        '[[axles]]\nid = "A1"\nx_m = 0.0\nwheel_diameter_m = 0.86\nteeth = 90\n'
    )
    return path


def _straight_track(marker: np.ndarray, azimuth_deg: float) -> GisTrack:
    """A 4 km straight line through the marker (at km 2000), 20 m vertices, ``azimuth_deg`` from north."""
    lat, lon, _ = ecef_to_geodetic(marker[None])
    east, north, _up = enu_basis(lat, lon)[0]
    a = np.radians(azimuth_deg)
    s = np.arange(0.0, 4000.0 + 1e-9, 20.0)
    pts = marker + np.outer(s - 2000.0, np.sin(a) * east + np.cos(a) * north)
    return GisTrack("TEST", "S", TrackLine.from_ecef(pts), s)


@pytest.mark.parametrize("case", sorted(CASES))
def test_real_files_import_and_position(case: str, tmp_path: Path) -> None:
    obs_file, nav_file, receiver, xyz, delta_h = CASES[case]
    out = tmp_path / "run"
    res = import_run([DATA / obs_file, DATA / nav_file], out, vehicle=_vehicle(tmp_path / "v.toml", receiver, delta_h))
    assert res.rows["gnss_obs"] > 50 and res.rows["gnss_nav"] >= 7
    run = read_run(out)
    g = run_gnss(run)
    assert g is not None and g.iono  # the navigation header's Klobuchar parameters came through
    marker = np.array(xyz)
    lat, lon, _ = ecef_to_geodetic(marker[None])
    up = enu_basis(lat, lon)[0][2]
    for azimuth in (0.0, 75.0):
        rep = position_report(run.run_id, g, _straight_track(marker, azimuth), 1, systems=("G",))
        e = rep.epochs
        assert len(e) == 3
        # unconstrained: the classical receiver, within tens of metres of the antenna
        lsq = e[e["lsq_available"]]
        assert len(lsq) >= 2
        from fieldlogs.gnss.geodesy import geodetic_to_ecef

        pos = geodetic_to_ecef(np.radians(lsq["lsq_lat"]), np.radians(lsq["lsq_lon"]), lsq["lsq_h_m"])
        assert np.linalg.norm(pos - (marker + delta_h * up), axis=1).max() < 50.0
        # constrained: on the track through the marker, a few metres, inside the stated bound
        ok = e[e["available"]]
        assert len(ok) == 3, e[["status", "n_used"]]
        err = np.abs(ok["km_m"].to_numpy() - 2000.0)
        assert err.max() < 6.0 and (err <= ok["uncertainty_m"].to_numpy()).all()
        assert (ok["n_used"] >= 5).all() and rep.availability["constrained"] == 1.0


def test_a_rinex3_event_record_with_blank_epoch_fields_is_skipped(tmp_path: Path) -> None:
    from fieldlogs.recorders.rinex import read_rinex

    src = DATA / CASES["netr9-rinex304"][0]
    lines = src.read_text().splitlines()
    end = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln)
    event = [">                              3  1", f"{'new site occupation (test)':<60}COMMENT"]
    edited = tmp_path / "event.rnx"
    edited.write_text("\n".join(lines[: end + 1] + event + lines[end + 1 :]) + "\n")
    a, b = read_rinex(src), read_rinex(edited)
    assert b.skipped["event records (epoch flags 2-5)"] == 1
    keep = [c for c in a.frames["gnss_obs"].columns if c != "receiver"]  # named after the file: no MARKER NAME
    assert b.frames["gnss_obs"][keep].equals(a.frames["gnss_obs"][keep])
