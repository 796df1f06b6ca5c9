"""SBAS end to end: the simulator's stream (independent encoder) decoded and applied, more
accurate than standalone on the same observations; standalone unchanged without a valid
message; the stream through UBX SFRBX; ``trainpos gnss position`` on a simulated run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.database import read_network
from fieldlogs.experiments import gnss as ex
from fieldlogs.gnss.observables import Epochs
from fieldlogs.gnss.sbas import SbasCorrections
from fieldlogs.recorders.ubx import read_ubx
from fieldlogs.recorders.ubx_raw import rawx_frames, sbas_sfrbx_frames
from fieldlogs.runs.handle import read_run
from fieldlogs.simulate.gnss.observations import Simulated
from fieldlogs.simulate.gnss.sbas_stream import sbas_stream
from tests.fieldlogs.gnss.runs import simulate_gnss_run

Case = tuple[ex.CaseSpec, Simulated, pd.DataFrame, pd.DataFrame]


@pytest.fixture(scope="module")
def case() -> Case:
    spec = ex.CaseSpec(seed=5, sbas=True)
    sim, _, _, corr, prior = ex._simulate(spec)
    assert corr is not None
    return spec, sim, corr, prior


def test_simulated_stream_is_clean_and_complete(case: Case) -> None:
    corr = case[2]
    sb = SbasCorrections.from_stream(corr)
    m = sb.messages
    assert m.dropped == {} and m.not_decoded == {} and m.n_valid == len(corr) and m.geo == 137
    assert set(corr["msg_type"]) == {1, 2, 3, 4, 6, 7, 10, 18, 25, 26}
    assert set(m.long_term["velocity"]) == {True} and len(m.iono) > 0


def test_sbas_corrected_epochs_are_more_accurate_than_standalone() -> None:
    seeds = (1, 2)
    alone = ex.summarise([ex.run_case(ex.CaseSpec(seed=s, sat_errors=True)) for s in seeds])
    sbas = ex.summarise([ex.run_case(ex.CaseSpec(seed=s, sbas=True)) for s in seeds])
    assert sbas["median_abs_err_m"] < 0.6 * alone["median_abs_err_m"]
    assert sbas["p99_abs_err_m"] < alone["p99_abs_err_m"]
    assert sbas["exceed_fraction"] <= 0.001 and sbas["constrained_availability"] >= alone["constrained_availability"]
    assert sbas["median_uncertainty_m"] < alone["median_uncertainty_m"]


def test_corrected_pseudoranges_lose_the_satellite_and_ionosphere_errors(case: Case) -> None:
    spec, sim, corr, prior = case
    with_sbas = ex._solve(sim, sim.obs, spec, corr, prior).observations
    alone = ex._solve(sim, sim.obs, ex.CaseSpec(seed=5, sat_errors=True), None, prior).observations
    truth = sim.truth.set_index(["t", "receiver"])
    rows = sim.rows.set_index(["t", "receiver", "sat"])

    def residual(e: Epochs) -> np.ndarray:
        """Corrected pseudorange − geometry − receiver clock − the receiver-side errors."""
        sel = e.usable & (e.t_run[:, None] > e.t_run[0] + 130.0)
        i, j = np.nonzero(sel)
        key = list(zip(e.t_run[i], e.receiver[i], strict=True))
        ant = truth.loc[key, ["x_m", "y_m", "z_m"]].to_numpy()
        clock = truth.loc[key, "clock_m"].to_numpy()
        pos = e.sat_pos[i, j]
        geo = np.linalg.norm(pos - ant, axis=1) + 7.2921151467e-5 / 299_792_458.0 * (
            pos[:, 0] * ant[:, 1] - pos[:, 1] * ant[:, 0]
        )
        r = e.pr_corr_m[i, j] - geo - clock
        local = rows.loc[list(zip(e.t_run[i], e.receiver[i], e.sat[i, j], strict=True))]
        return np.asarray(
            r - local["multipath_m"].to_numpy() - local["noise_m"].to_numpy() - local["nlos_m"].to_numpy()
        )

    r_sbas, r_alone = residual(with_sbas), residual(alone)
    assert np.sqrt(np.mean(r_sbas**2)) < 0.5 * np.sqrt(np.mean(r_alone**2))
    assert np.sqrt(np.mean(r_sbas**2)) < 0.8


def test_no_valid_message_leaves_the_standalone_solution_unchanged(case: Case) -> None:
    spec, sim, corr, prior = case
    from fieldlogs.gnss.position import PositionConfig, position_run
    from fieldlogs.gnss.skymask import load_mask

    broken = corr.assign(message_hex=corr["message_hex"].str[:56] + "00000000")
    sb = SbasCorrections.from_stream(broken)
    assert sb.empty and sb.messages.dropped == {"bad_crc": len(corr)}
    cfg, mask, track = PositionConfig(systems=spec.systems), load_mask(spec.sky), ex._track().grid
    a = position_run(sim.obs, sim.nav, track, ex.ANTENNAS, iono=sim.iono, sky_mask=mask, prior=prior, cfg=cfg)
    b = position_run(sim.obs, sim.nav, track, ex.ANTENNAS, iono=sim.iono, sky_mask=mask, prior=prior, cfg=cfg, sbas=sb)
    pd.testing.assert_frame_equal(a.epochs, b.epochs)


def test_the_stream_through_ubx_sfrbx(case: Case, tmp_path: Path) -> None:
    sim = case[1]
    sb = sbas_stream(sim, seed=3).iloc[:40]
    obs = sim.obs[sim.obs["receiver"] == "rx1"].assign(gnss_time_s=lambda d: np.round(d["gnss_time_s"], 6))
    frames = sorted([*rawx_frames(obs), *sbas_sfrbx_frames(sb)], key=lambda x: x[0])
    p = tmp_path / "rx1.ubx"
    p.write_bytes(b"".join(f for _, f in frames))
    back = read_ubx(p).frames["gnss_sbas"]
    assert back["message_hex"].tolist() == sb["message_hex"].tolist()
    assert back["prn"].tolist() == sb["prn"].tolist() and back["msg_type"].tolist() == sb["msg_type"].tolist()
    epochs = np.unique(obs["gnss_time_s"].to_numpy())
    after = epochs[np.searchsorted(epochs, sb["gnss_time_s"].to_numpy(), side="left")]
    np.testing.assert_allclose(back["gnss_time_s"], after, atol=1e-6)  # the next epoch: an upper bound
    a, b = SbasCorrections.from_stream(sb).messages, SbasCorrections.from_stream(back).messages
    assert b.dropped == {}
    np.testing.assert_array_equal(a.fast["t_of"], b.fast["t_of"])  # the same time of applicability


def test_gnss_position_on_a_simulated_run_with_an_msas_stream(sample_db: Path, tmp_path: Path) -> None:
    run = simulate_gnss_run(
        read_network(sample_db), tmp_path / "run", seed=8, length_m=2500.0, gnss_raw={"sbas": True, "systems": ["G"]}
    )
    assert (run / "gnss_sbas.parquet").is_file() or (run / "gnss_sbas.csv").is_file()
    off = tmp_path / "off.toml"
    off.write_text("[gnss]\nsbas = false\n")
    truth = read_run(run).stream("truth")
    assert truth is not None
    errs = {}
    for name, extra in (("sbas", []), ("alone", ["--config", str(off)])):
        res = CliRunner().invoke(
            app, ["gnss", "position", str(run), "--db", str(sample_db), "--format", "json", *extra]
        )
        assert res.exit_code == 0, res.output
        doc = json.loads(res.output)
        ok = [x for x in doc["epochs"] if x["available"] and x["t"] > 90.0]
        e = np.array([x["km_m"] for x in ok]) - np.interp([x["t"] for x in ok], truth["t"], truth["km_m"])
        errs[name] = (np.median(np.abs(e)), doc["sbas"])
    assert errs["alone"][1] is None
    s = errs["sbas"][1]
    assert s["prn"] == 137 and s["dropped"] == {} and s["rows"]["corrected"] > 0
    assert errs["sbas"][0] < errs["alone"][0]


def test_an_mt27_delta_udre_widens_the_corrected_rows_sigma_only(case: Case) -> None:
    from fieldlogs.simulate.gnss import sbas_encode as enc

    spec, sim, corr, prior = case
    t_rx = float(corr["gnss_time_s"].iloc[0]) - 0.5
    mt27 = enc.mt27(0, 1, 1, 0, 4, 4, [])  # δUDRE 2 inside and outside: everywhere
    extra = pd.DataFrame(
        {"t": [float(corr["t"].iloc[0]) - 0.5], "gnss_time_s": [t_rx], "prn": [137], "msg_type": [27],
         "message_hex": [mt27.hex().upper()], "valid": [1]}
    )  # fmt: skip
    with27 = pd.concat([extra, corr], ignore_index=True)
    a = ex._solve(sim, sim.obs, spec, corr, prior).observations
    b = ex._solve(sim, sim.obs, spec, with27, prior).observations
    corrected = a.present & np.isfinite(a.corr_udre_m)
    assert corrected.sum() > 1000
    assert (b.sigma_m[corrected] > a.sigma_m[corrected] + 0.1).all()
    other = a.present & ~corrected
    np.testing.assert_array_equal(b.sigma_m[other], a.sigma_m[other])


def test_two_geos_switch_on_time_out_and_mt0_each_epoch_as_its_geo_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    spec = ex.CaseSpec(seed=5, sbas=True, two_geos=True)
    _, _, _, corr, _ = ex._simulate(spec)
    assert corr is not None and set(corr["prn"]) == {129, 137}
    sb = SbasCorrections.from_stream(corr)
    t_first = float(corr["gnss_time_s"].iloc[0]) - float(corr["t"].iloc[0])  # gnss time of run t = 0
    at = sb.active(t_first + np.array([100.0, 210.0, 300.0, 420.0, 460.0, 550.0]))
    assert at.tolist() == [137, 137, 129, 129, 137, 137] and sb.timeline.switches() == 2
    two = ex.run_case(spec).epochs
    real = ex._simulate
    alone = {}
    for prn in (137, 129):  # each GEO's own messages of the same stream, alone

        def one_geo(sp: ex.CaseSpec, prn: int = prn) -> tuple:  # type: ignore[type-arg]
            sim, t, s, both, prior = real(sp)
            assert both is not None
            return sim, t, s, both[both["prn"] == prn], prior

        monkeypatch.setattr(ex, "_simulate", one_geo)
        alone[prn] = ex.run_case(spec).epochs
    t = two["t"].to_numpy() - two["t"].min()
    # the clock-aided epochs coast the receiver clock over the epochs before, across a switch too
    own = ~two["clock_aided"].to_numpy()
    for prn, sel in ((137, (t < 200.0) | (t >= 450.0 + 1.125)), (129, (t >= 200.0 + 1.125 + 18.0) & (t < 450.0))):
        sel = sel & own & ~alone[prn]["clock_aided"].to_numpy()
        assert sel.sum() > 300
        np.testing.assert_allclose(two["s_m"].to_numpy()[sel], alone[prn]["s_m"].to_numpy()[sel], atol=1e-6)
    assert (two["available"] == alone[137]["available"]).all()
