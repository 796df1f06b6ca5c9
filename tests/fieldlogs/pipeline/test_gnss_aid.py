"""The GNSS aid in the pipeline [S002]: corrections below the margin keep |error| ≤ margin and
shrink the margins, the GNSS initial position on a GPS-decided track, and the refusals (no
heights, orthometric heights, a receiver without an antenna)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.gnss.config import GnssConfig
from fieldlogs.pipeline.config import GpsConfig, PipelineConfig
from fieldlogs.pipeline.run import PipelineResult, run_pipeline
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.runs.handle import read_run
from schemas.enums import EventType
from tests.fieldlogs.gnss.runs import simulate_gnss_run


@pytest.fixture(scope="module")
def network(sample_db: Path) -> Network:
    return read_network(sample_db)


@pytest.fixture(scope="module")
def gnss_run(network: Network, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulate_gnss_run(network, tmp_path_factory.mktemp("gnss") / "run", seed=11)


def _run(folder: Path, network: Network, cfg: PipelineConfig | None = None) -> PipelineResult:
    return run_pipeline(read_run(folder), network, cfg or PipelineConfig())


def _claimed(res: PipelineResult) -> pd.DataFrame:
    assert res.truth is not None
    cmp = compare_with_truth(res.positions, res.truth)
    return cmp[cmp["claimed"]]


def _types(res: PipelineResult) -> pd.Series:
    return res.events["type"].astype(str)


def test_corrections_keep_the_error_inside_a_smaller_margin(gnss_run: Path, network: Network) -> None:
    off = _run(gnss_run, network, PipelineConfig(gnss=GnssConfig(enabled=False)))
    on = _run(gnss_run, network)
    assert not (_types(off).str.startswith("gnss")).any()
    n_corr = int((_types(on) == EventType.GNSS_CORRECTION).sum())
    assert n_corr >= 20
    c_on, c_off = _claimed(on), _claimed(off)
    assert c_on["within_margin"].all() and not c_on["wrong_track"].any()
    assert np.percentile(c_on["margin_m"], 90) < 0.5 * np.percentile(c_off["margin_m"], 90)
    assert c_on["margin_m"].max() < c_off["margin_m"].max()
    assert (on.positions["last_fix_source"] == "gnss").any()


def test_a_gnss_correction_is_no_absolute_fix_for_the_correction_percentage(gnss_run: Path, network: Network) -> None:
    on = _run(gnss_run, network)
    ev = on.events
    gnss = ev[ev["type"] == EventType.GNSS_CORRECTION]
    assert gnss["correction_pct"].isna().all() and gnss["correction_m"].notna().all()
    detail = json.loads(gnss["detail"].iloc[0])
    assert detail["uncertainty_m"] < detail["margin_m"] - GnssConfig().correction_gain_m
    # the balise corrections' % is still over the distance since the previous balise/feature fix
    bal = ev[(ev["type"] == EventType.BALISE_CORRECTION) & ev["correction_pct"].notna()]
    dist = bal["detail"].map(lambda d: json.loads(d)["distance_since_correction_m"])
    assert (dist > 1000.0).all()
    assert (
        on.summary["n_balise_corrections"]
        == _run(gnss_run, network, PipelineConfig(gnss=GnssConfig(enabled=False))).summary["n_balise_corrections"]
    )


def test_gnss_sets_the_initial_position_on_the_gps_decided_track(gnss_run: Path, network: Network) -> None:
    cfg = PipelineConfig(gps=GpsConfig(allow_initial=False))
    folder = gnss_run.parent / "no-balise"
    simulate_gnss_run(network, folder, seed=11, sensors={"balise": False})
    res = _run(folder, network, cfg)
    ev = res.events
    first = ev[ev["type"] == EventType.INITIAL_POSITION_GNSS]
    assert len(first) == 1
    decision = ev[ev["type"] == EventType.TRACK_DECISION]
    assert float(first["t"].iloc[0]) >= float(decision["t"].iloc[0])
    detail = json.loads(first["detail"].iloc[0])
    assert detail["track"] == "D" and detail["k"] == 1
    c = _claimed(res)
    assert c["within_margin"].all() and not c["wrong_track"].any()
    assert (res.positions.loc[res.positions["state"] != "undetermined", "last_fix_source"].iloc[0]) == "gnss"
    # without the GNSS aid, the same run has no position at all
    off = _run(folder, network, replace(cfg, gnss=GnssConfig(enabled=False)))
    assert (off.positions["state"] == "undetermined").all()


def _refusals(res: PipelineResult) -> list[dict[str, object]]:
    ev = res.events
    return [json.loads(d) for d in ev.loc[ev["type"] == EventType.GNSS_REFUSED, "detail"]]


def test_no_heights_on_the_track_is_a_notice_and_no_correction(gnss_run: Path, network: Network) -> None:
    tables = {k: v.copy() for k, v in network.tables.items()}
    tables["gis"]["height_m"] = np.nan
    res = _run(gnss_run, Network(tables, origin="no-heights"))
    assert [r["reason"] for r in _refusals(res)] == ["no_heights"]
    assert not (_types(res) == EventType.GNSS_CORRECTION).any()


def test_orthometric_heights_are_refused(gnss_run: Path, network: Network) -> None:
    meta = {**network.meta, "height_datum": "orthometric", "geoid_model": "GSIGEO2011"}
    net = Network(dict(network.tables), meta=meta, origin="ortho")
    res = _run(gnss_run, net)
    assert [r["reason"] for r in _refusals(res)] == ["orthometric_heights"]
    assert not (_types(res) == EventType.GNSS_CORRECTION).any()


def test_a_receiver_without_an_antenna_is_refused_once(gnss_run: Path, network: Network, tmp_path: Path) -> None:
    import shutil

    folder = tmp_path / "no-antenna"
    shutil.copytree(gnss_run, folder)
    meta = json.loads((folder / "run.json").read_text())
    meta["vehicle"]["antennas"] = meta["vehicle"]["antennas"][:1]
    (folder / "run.json").write_text(json.dumps(meta))
    res = _run(folder, network)
    assert [r["reason"] for r in _refusals(res)] == ["no_antenna"]
    assert not (_types(res) == EventType.GNSS_CORRECTION).any()


def _tracks_swapped(network: Network) -> Network:
    """The sample network with the GIS geometry of tracks U and D exchanged (balises and km
    unchanged): the balises put the train on D, whose grid now runs where U really is."""
    g = network.tables["gis"]
    key = ["line_code", "km_m"]
    u, d = g[g["track"] == "U"].set_index(key), g[g["track"] == "D"].set_index(key)
    swapped = g.copy()
    for mask, other in ((g["track"] == "D", u), (g["track"] == "U", d)):
        idx = pd.MultiIndex.from_frame(g.loc[mask, key])
        for c in ("lat", "lon", "height_m"):
            swapped.loc[mask, c] = other[c].reindex(idx).to_numpy()
    return Network({**network.tables, "gis": swapped}, meta=network.meta, origin="tracks swapped")


def test_fits_far_better_on_the_other_track_are_reported_and_stop_the_corrections(
    gnss_run: Path, network: Network
) -> None:
    """Issue 17 (must have 4): the constrained solution never chooses the track, but fits far
    better on the other track are evidence: ``gnss_track_disagrees`` once, and no GNSS
    correction while it lasts. With the default threshold (standalone σ) the 3.8 m between the
    tracks leaves it undecided (bench/NOTES.md); with 4 it decides within the first 2 minutes."""
    bad = _tracks_swapped(network)
    cfg = PipelineConfig(gnss=GnssConfig(track_chi2=4.0))
    res = _run(gnss_run, bad, cfg)
    ev, types = res.events, _types(res)
    dis = ev[types == EventType.GNSS_TRACK_DISAGREES]
    assert len(dis) == 1
    assert json.loads(dis["detail"].iloc[0]) == {"track": "D", "gnss_track": "U", "window_s": 60.0}
    t_dis = float(dis["t"].iloc[0])
    assert t_dis < 150.0
    corr_t = ev.loc[types == EventType.GNSS_CORRECTION, "t"].to_numpy(dtype=float)
    assert len(corr_t) > 0 and (corr_t < t_dis).all()  # none after the evidence: it lasts to the end
    # the same threshold on the true network: no disagreement, corrections to the end
    res = _run(gnss_run, network, cfg)
    assert not (_types(res) == EventType.GNSS_TRACK_DISAGREES).any()
    late = res.events.loc[_types(res) == EventType.GNSS_CORRECTION, "t"].to_numpy(dtype=float)
    assert (late > t_dis).any()
