"""A simulated run's raw GNSS on the DB's GIS track (``trainsim``, ``gis``, ``ontrack``):
solutions agree with the truth within their stated uncertainty, the km mapping is exact at the
grid points, the fits on the wrong track are worse, and switching raw GNSS on changes no
other stream of the simulator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.gnss.config import GnssConfig, position_config
from fieldlogs.gnss.gis import GnssTrackError, gis_track
from fieldlogs.gnss.observables import epoch_keys
from fieldlogs.gnss.ontrack import TrackEvidence, TrackSolutions, solve_on_track
from fieldlogs.gnss.runinputs import iono_params, run_gnss
from fieldlogs.quality.checks import DbRefs, check_run
from fieldlogs.runs.handle import read_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from tests.fieldlogs.gnss.runs import gnss_scenario, simulate_gnss_run


@pytest.fixture(scope="module")
def network(sample_db: Path) -> Network:
    return read_network(sample_db)


@pytest.fixture(scope="module")
def run_dir(network: Network, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulate_gnss_run(network, tmp_path_factory.mktemp("ontrack") / "run", seed=5, length_m=3000.0)


@pytest.fixture(scope="module")
def solutions(run_dir: Path, network: Network) -> dict[str, TrackSolutions]:
    g = run_gnss(read_run(run_dir))
    assert g is not None
    cfg = position_config(GnssConfig())
    return {tr: solve_on_track(g, gis_track(network, "0420", tr), 1, cfg) for tr in ("D", "U")}


def test_the_simulated_run_is_a_clean_run_with_vehicle_and_gnss_blocks(run_dir: Path, network: Network) -> None:
    run = read_run(run_dir)
    findings = [f for f in check_run(run, DbRefs.from_network(network)) if str(f.severity) == "error"]
    assert findings == []
    assert [a["receiver"] for a in run.meta.vehicle["antennas"]] == ["rx1", "rx2"]  # type: ignore[index]
    assert set(iono_params(run.meta.gnss)) == {"gps_alpha", "gps_beta"}  # type: ignore[arg-type]
    obs = run.stream("gnss_obs")
    assert obs is not None and set(obs["receiver"]) == {"rx1", "rx2"}
    assert set(obs["sat"].str[0]) == {"G", "E", "J"}


def test_solutions_on_the_true_track_are_within_their_uncertainty(run_dir: Path, solutions: dict) -> None:
    truth = read_run(run_dir).stream("truth")
    assert truth is not None
    best = solutions["D"].best
    assert len(best) >= 0.95 * read_run(run_dir).stream("gnss_obs")["t"].nunique()  # type: ignore[index]
    err = best["km_m"].to_numpy() - np.interp(best["t"], truth["t"], truth["km_m"])
    assert np.median(np.abs(err)) < 1.5 and np.abs(err).max() < 10.0
    assert (np.abs(err) <= best["uncertainty_m"].to_numpy()).all()


def test_the_wrong_track_fits_worse(solutions: dict) -> None:
    wrong = TrackEvidence.between(solutions["U"], solutions["D"])  # in force: U; other: the true D
    right = TrackEvidence.between(solutions["D"], solutions["U"])
    assert wrong.excess.size > 100 and np.median(wrong.excess) > 3.0 and np.mean(wrong.excess > 0) > 0.9
    assert np.median(right.excess) < 0.0
    # the excess follows the satellites' geometry across the track: ~5 a minute into this run
    assert wrong.far_better(60.0, 60.0, 20, chi2=4.0, share=0.9)
    assert not right.far_better(60.0, 60.0, 20, chi2=4.0, share=0.9)
    assert not wrong.far_better(60.0, 60.0, 61, chi2=4.0, share=0.9)  # too few epochs to judge
    assert not wrong.far_better(60.0, 60.0, 20, chi2=GnssConfig().track_chi2, share=0.9)  # the default: undecided


def test_km_of_s_is_exact_at_the_grid_points(network: Network) -> None:
    gt = gis_track(network, "0420", "U")
    g = network.gis
    km = np.sort(g.loc[(g["line_code"] == "0420") & (g["track"] == "U"), "km_m"].to_numpy(dtype=float))
    np.testing.assert_allclose(gt.km, km)
    np.testing.assert_allclose(gt.km_of_s(gt.line.s), km)
    np.testing.assert_allclose(gt.s_of_km(gt.km_of_s([-5.0, 123.4, gt.line.length_m + 7.0])), [-5.0, 123.4,
                               gt.line.length_m + 7.0])  # fmt: skip


def test_a_track_the_db_does_not_have_is_refused(network: Network) -> None:
    with pytest.raises(GnssTrackError) as exc:
        gis_track(network, "0420", "S")
    assert exc.value.reason == "unknown_track" and exc.value.exit_code == 1


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.0, 1000.0, allow_nan=False), min_size=1, max_size=40, unique=True),
    st.floats(-0.005, 0.005),
)
def test_epoch_keys_pair_receivers_within_their_clock_offsets(base: list[float], offset: float) -> None:
    t0 = np.round(np.array(sorted(base)) * 10.0) / 10.0  # epochs ≥ 0.1 s apart (10 Hz receivers)
    t0 = np.unique(t0)
    keys = epoch_keys(np.concatenate([t0, t0 + offset]))
    n = t0.size
    np.testing.assert_array_equal(keys[:n], keys[n:])
    assert np.unique(keys).size == n


def test_raw_gnss_changes_no_other_stream(network: Network) -> None:
    sc = gnss_scenario(network, length_m=1500.0)
    on = simulate_run(network, scenario_from_dict(sc), seed=3)
    off = simulate_run(network, scenario_from_dict({**sc, "gnss_raw": {"enabled": False}}), seed=3)
    assert {"gnss_obs", "gnss_nav"} <= set(on.streams) and not {"gnss_obs", "gnss_nav"} & set(off.streams)
    for name, frame in off.streams.items():
        pd.testing.assert_frame_equal(frame, on.streams[name])
    assert off.meta.vehicle is None and off.meta.gnss is None
    assert "gnss_raw" not in off.meta.extra["sim_truth"]


def test_the_divergence_monitor_is_a_gnss_setting() -> None:
    """``[gnss] max_divergence_mps`` reaches the solver; 0 turns the monitor off."""
    assert position_config(GnssConfig()).max_divergence_mps == 0.1
    assert position_config(GnssConfig(max_divergence_mps=0.25)).max_divergence_mps == 0.25
    assert position_config(GnssConfig(max_divergence_mps=0.0)).max_divergence_mps is None
