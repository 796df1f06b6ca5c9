"""Constellation and observation simulator; the seeded headline statistics (not timed)."""

from __future__ import annotations

import numpy as np
import pytest

from fieldlogs.experiments.gnss import CaseSpec, run_case, summarise
from fieldlogs.gnss.constants import NAV_COLUMNS, OBS_COLUMNS, WEEK_S
from fieldlogs.gnss.ephemeris import nav_table, satellite_states, select_ephemeris
from fieldlogs.gnss.geodesy import azimuth_elevation, geodetic_to_ecef
from fieldlogs.gnss.position import PositionConfig, position_run
from fieldlogs.gnss.track import Antenna
from fieldlogs.simulate.gnss.constellation import TOE_SPACING_S, constellation_nav
from fieldlogs.simulate.gnss.observations import Corridor, ErrorSpec, ReceiverSpec, Section, simulate
from fieldlogs.simulate.gnss.scenario import run_profile, synthetic_track, trajectory

T0 = 2300 * WEEK_S + 5 * 3600.0


def test_constellation_layout() -> None:
    nav = constellation_nav(T0, T0 + 3600.0, seed=9)
    assert list(nav.columns) == list(NAV_COLUMNS)
    sats = np.asarray(nav["sat"].unique(), dtype=str)
    assert sum(s.startswith("G") for s in sats) == 31
    assert sum(s.startswith("E") for s in sats) == 24
    assert sorted(s for s in sats if s.startswith("J")) == ["J01", "J02", "J03", "J04"]
    for sys, spacing in TOE_SPACING_S.items():
        toe = np.sort(
            (nav.loc[nav["sat"] == f"{sys}01", "week"] * WEEK_S + nav.loc[nav["sat"] == f"{sys}01", "Toe"]).unique()
        )
        assert np.all(np.diff(toe) == spacing)
    table = nav_table(nav)
    t = np.full(sats.size, T0 + 1800.0)
    st = satellite_states(table, select_ephemeris(table, sats, t), t)
    r = np.linalg.norm(st.pos, axis=1)
    gps, gal = np.char.startswith(sats, "G"), np.char.startswith(sats, "E")
    assert np.all(np.abs(r[gps] - 26_560e3) < 600e3)
    assert np.all(np.abs(r[gal] - 29_600e3) < 50e3)
    rx = geodetic_to_ecef(np.radians(35.7), np.radians(139.7), 40.0)
    _, el = azimuth_elevation(rx, st.pos[sats == "J03"])
    assert 40.0 < float(np.degrees(el[0])) < 55.0  # the GEO at 127° E seen from Tokyo


def test_consecutive_records_describe_the_same_orbit() -> None:
    nav = constellation_nav(T0, T0 + 3 * 3600.0, seed=9, systems=("G",))
    g = nav[nav["sat"] == "G03"].reset_index(drop=True)
    table = nav_table(g)
    t = np.full(table.size, table.toe_s[1] + 1000.0)
    st = satellite_states(table, np.arange(table.size), t)
    assert np.max(np.linalg.norm(st.pos - st.pos[1], axis=1)) < 1e-3


def _zero_errors() -> ErrorSpec:
    return ErrorSpec(
        sis_sigma_m={"G": 0.0, "E": 0.0, "J": 0.0}, iono_run_sigma=0.0, iono_sat_sigma=0.0, tropo_run_sigma=0.0,
        mp_zenith_m=0.0, mp_low_m=0.0, noise_45_m=0.0, p_nlos=0.0,
    )  # fmt: skip


def test_error_free_simulation_is_solved_exactly() -> None:
    """Simulator (exact light time and Earth rotation) and solvers (first-order Sagnac term)
    share only the ICD: without errors (and without carrier smoothing, whose ionospheric
    divergence is centimetres) the unconstrained fix is within 1 cm, the constrained
    along-track position within 0.15 m (the 20 m grid's chords and 2 cm survey noise)."""
    tr = synthetic_track()
    s = run_profile(tr.truth.length_m, 120.0, 1.0, 25.0, 800.0, 3000.0)
    traj = trajectory(tr, s, T0, 1.0)
    nav = constellation_nav(T0, T0 + 200.0, seed=1)
    rx = [ReceiverSpec("rx1", 8.0, clock_walk_m=0.0), ReceiverSpec("rx2", -8.0, clock_bias_s=-4e-4, clock_walk_m=0.0)]
    sim = simulate(traj, nav, rx, Corridor(), seed=3, errors=_zero_errors())
    assert list(sim.obs.columns) == list(OBS_COLUMNS)
    ants = {"rx1": Antenna(8.0, 0.0, 3.8), "rx2": Antenna(-8.0, 0.0, 3.8)}
    res = position_run(sim.obs, sim.nav, tr.grid, ants, iono=sim.iono, cfg=PositionConfig(smoothing_s=None))
    tb = res.epochs
    assert tb["available"].all()
    err = tb["s_m"] - np.interp(tb["t"], traj.t, traj.s)
    assert err.abs().max() < 0.15
    lsq = tb[["lsq_x_m", "lsq_y_m", "lsq_z_m"]].to_numpy() - sim.truth[["x_m", "y_m", "z_m"]].to_numpy()
    assert np.linalg.norm(lsq, axis=1).max() < 0.01
    assert tb["antenna_distance_ok"].all()
    assert tb["antenna_distance_real_m"].iloc[0] == pytest.approx(16.0, abs=0.01)


def test_corridor_blocks_by_side() -> None:
    cor = Corridor(
        (Section(0.0, 100.0, "left", 60.0), Section(100.0, 200.0, "tunnel"), Section(200.0, 300.0, "cutting", 20.0))
    )
    left, right, blocked, buildings = cor.masks(np.array([50.0, 150.0, 250.0, 400.0]))
    np.testing.assert_array_equal(left, [60.0, 0.0, 20.0, 0.0])
    np.testing.assert_array_equal(right, [0.0, 0.0, 20.0, 0.0])
    np.testing.assert_array_equal(blocked, [False, True, False, False])
    np.testing.assert_array_equal(buildings, [True, False, False, False])


def test_headline_statistics_on_a_few_seeded_runs() -> None:
    """The bench's headline on 3 runs (bench/bench_gnss.py runs 50): GPS only, west half of the
    sky blocked: the constrained solution is available where the unconstrained one mostly is
    not, metres along the track, inside its uncertainty; a 50 m step is excluded at once."""
    runs = [run_case(CaseSpec(seed=s)) for s in (11, 12, 13)]
    s = summarise(runs)
    assert s["unconstrained_availability"] <= 0.5
    assert s["constrained_availability"] >= 0.9
    assert s["median_abs_err_m"] <= 3.0
    assert s["p99_abs_err_m"] <= 15.0
    assert s["exceed_fraction"] <= 0.001
    f = summarise([run_case(CaseSpec(seed=s, fault="step")) for s in (11, 12)])
    assert f["fault_epochs"] > 100
    assert f["fault_not_excluded_after_2_epochs"] == 0.0
    assert f["fault_exceed_fraction"] <= 0.001


def test_trajectory_from_geodetic_matches_ecef() -> None:
    tr = synthetic_track()
    s = np.array([100.0, 200.0])
    ref = trajectory(tr, s, T0, 1.0)
    from fieldlogs.gnss.geodesy import ecef_to_geodetic
    from fieldlogs.simulate.gnss.observations import Trajectory

    lat, lon, h = ecef_to_geodetic(ref.ref_ecef)
    geo = Trajectory.from_geodetic(ref.t, np.degrees(lat), np.degrees(lon), h, np.degrees(ref.heading_rad), s)
    np.testing.assert_allclose(geo.ref_ecef, ref.ref_ecef, atol=1e-6)
    np.testing.assert_allclose(geo.heading_rad, ref.heading_rad)
