"""Each unit on its own cab's sensors [S003 §2] (:mod:`fieldlogs.pipeline.units`): the R cab's
own streams as unit R's, the fallback to the turned view, ``units_disagree`` events, and
simulated turnbacks whose units agree or whose R wheel is off."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cli.main import app
from dbtools.database import read_network
from fieldlogs.pipeline.cycles import Cycles, build_cycles
from fieldlogs.pipeline.units import compare_units, disagreement_events, r_sources, r_view, unit_run, with_events
from fieldlogs.runs.handle import Run, read_run
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.samples_net import network_sample_scenarios
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.enums import EventType
from schemas.units import G

TEETH, D = 30, 3 / np.pi  # 0.1 m per pulse


def _left_turn(folder: Path, own: bool) -> Path:
    """2 s of a steady left turn at 10 m/s on R = 500 m, the F end leading (hand values of
    ``tests/fieldlogs/simulate/test_cab_r.py``): ωz = 0.02, ay = 0.2 at the reference point;
    the R cab's IMU 9.5 m behind reads ax = −0.0038, ay = −0.2 in its frame; each tacho 10
    pulses per cycle, the F's direction +1, the R's −1; the R GPS antenna at x = −9.5 m."""
    t_imu = np.round(np.arange(200) * 0.01, 2)
    t_tacho = np.round(np.arange(21) * 0.1, 1)

    def imu(ax: float, ay: float) -> pd.DataFrame:
        n = len(t_imu)
        return pd.DataFrame(
            {"t": t_imu, "ax": ax, "ay": ay, "az": G, "wx": np.zeros(n), "wy": np.zeros(n), "wz": np.full(n, 0.02)}
        )

    def tacho(sense: int) -> pd.DataFrame:
        return pd.DataFrame({"t": t_tacho, "pulses": np.arange(21) * 10, "direction": [0] + [sense] * 20})

    def gps(lat: float) -> pd.DataFrame:
        return pd.DataFrame({"t": [0.0, 1.0, 2.0], "lat": lat, "lon": 139.4, "fix": 2, "nsat": 10, "hdop": 0.8})

    streams = {
        "imu": imu(0.0, 0.2),
        "tacho": tacho(1),
        "gps": gps(35.9),
        "cab": pd.DataFrame({"t": [0.0], "direction": ["F"]}),
    }
    vehicle = None
    if own:
        streams |= {"imu_r": imu(-0.0038, -0.2), "tacho_r": tacho(-1), "gps_r": gps(35.91)}
        vehicle = {
            "vehicle_id": "V",
            "vehicle_kind": "train",
            "length_m": 20.0,
            "reference": "centre",
            "front_x_m": 10.0,
            "tacho_axle": "A1",
            "axles": [{"id": "A1", "x_m": 8.0, "wheel_diameter_m": D, "teeth": TEETH}],
            "gps_antenna": {"x_m": 0.0, "y_m": 0.0},
            "gps_antenna_r": {"x_m": -9.5, "y_m": 0.0},
            "imu_r": {"x_m": -9.5, "y_m": 0.0, "z_m": 0.0},
        }
    meta = RunMeta("LT", "V", "train", D, TEETH, "2026-01-15T10:00:00+09:00", vehicle=vehicle)
    return write_run(folder, meta, streams)


def _cycles(run: Run) -> Cycles:
    return build_cycles(
        tacho=run.stream("tacho"), imu=run.stream("imu"), cab=run.stream("cab"), wheel_diameter_m=D, teeth=TEETH
    )


def test_a_left_turn_seen_by_each_unit_on_its_own_sensors(tmp_path: Path) -> None:
    """Unit R reads the R cab's streams as they are: it moves toward its own back (motion −1,
    its cab R) at 10 m/s with ωz = +0.02 and ay = −0.2, so κ = ωz/|v| = +1/500 (left in the
    direction of travel) for both units; its GPS antenna is 9.5 m ahead in its own frame."""
    run = read_run(_left_turn(tmp_path / "lt", own=True))
    assert [f for f in run.findings if f.severity == "error"] == []
    assert r_sources(run) == {"imu": "imu_r", "tacho": "tacho_r", "gps": "gps_r"}
    assert r_view(r_sources(run)) == "the R cab's own imu_r, tacho_r, gps_r"
    view = unit_run(run, "R", tmp_path / "R")
    for name in ("imu", "tacho", "gps"):
        pd.testing.assert_frame_equal(view.stream(name), run.stream(f"{name}_r"))
    assert view.stream("cab")["direction"].tolist() == ["R"]
    assert view.meta is not None and view.meta.vehicle is not None
    assert view.meta.vehicle["gps_antenna"]["x_m"] == 9.5 and view.meta.vehicle["imu"]["x_m"] == 9.5
    assert view.meta.vehicle["gps_antenna_r"]["x_m"] == 0.0
    assert not (tmp_path / "R" / "imu_r.parquet").exists()
    cf, cr = _cycles(run), _cycles(view)
    moving = slice(2, None)
    assert (cf.motion[moving] == 1).all() and (cr.motion[moving] == -1).all()
    for c, ay in ((cf, 0.2), (cr, -0.2)):
        assert c.v_pulse[moving] == pytest.approx(10.0)
        assert c.imu["wz"][moving] / c.v_pulse[moving] == pytest.approx(1 / 500)
        assert c.imu["ay"][moving] == pytest.approx(ay)


def test_r_streams_without_their_places_in_the_vehicle_block(tmp_path: Path) -> None:
    """R cab streams on a vehicle block that gives their sensors no place: unit R's GPS antenna
    is the reference point (not the F antenna seen from the other end), its IMU section absent;
    the view's run.json is a valid run."""
    folder = _left_turn(tmp_path / "lt", own=True)
    meta = read_run(folder).meta
    assert meta is not None and meta.vehicle is not None
    vehicle = {k: v for k, v in meta.vehicle.items() if not k.endswith("_r")}
    vehicle["gps_antenna"] = {"x_m": 4.0, "y_m": 0.5}
    vehicle["imu"] = {"x_m": 2.0, "y_m": 0.0, "z_m": 1.0}
    run = read_run(write_run(tmp_path / "plain", replace(meta, vehicle=vehicle), read_run(folder).load_all()))
    view = unit_run(run, "R", tmp_path / "R")
    assert view.meta is not None and view.meta.vehicle is not None
    assert view.meta.vehicle["gps_antenna"] == {"x_m": -0.0, "y_m": -0.0}
    assert view.meta.vehicle["gps_antenna_r"] == {"x_m": -4.0, "y_m": -0.5}
    assert "imu" not in view.meta.vehicle and view.meta.vehicle["imu_r"]["x_m"] == -2.0
    assert [f for f in view.findings if f.severity == "error"] == []


def test_without_r_streams_unit_r_turns_the_f_ones_round(tmp_path: Path) -> None:
    run = read_run(_left_turn(tmp_path / "lt", own=False))
    assert r_sources(run) == {"imu": "imu", "tacho": "tacho", "gps": "gps"}
    assert r_view(r_sources(run)).startswith("the F cab's streams turned round")
    view = unit_run(run, "R", tmp_path / "R")
    assert view.stream("imu")["ay"].tolist() == [-0.2] * 200
    assert view.stream("tacho")["direction"].tolist() == [0] + [-1] * 20
    pd.testing.assert_frame_equal(view.stream("gps"), run.stream("gps"))


def test_disagreement_events_hand_computed() -> None:
    """The hand case of test_units.py: cycles 2 (10.5 m > 5 + 5) and 3 (same km on tracks A and
    B) make one span from t = 0.2 to 0.3; its worst |d| is cycle 2's."""
    d, u, a = "determined", "undetermined", "ambiguous"
    t = np.arange(6) * 0.1
    f = pd.DataFrame(
        {"t": t, "km_m": [100.0, 110, 120, 130, 140, 150], "margin_m": [5.0] * 6, "state": [u, d, d, d, d, a],
         "track_id": ["A"] * 6}
    )  # fmt: skip
    r = pd.DataFrame(
        {"t": t, "km_m": [np.nan, 107.0, 109.5, 130.0, 131.0, 130.0], "margin_m": [9.0, 5, 5, 5, 4, 16],
         "state": [u, d, d, d, d, d], "track_id": ["", "A", "A", "B", "A", "A"]}
    )  # fmt: skip
    frame, _ = compare_units(f, r)
    ev_f, ev_r = disagreement_events(frame, "F"), disagreement_events(frame, "R")
    assert ev_f["type"].tolist() == ev_r["type"].tolist() == [EventType.UNITS_DISAGREE.value]
    assert ev_f["t"].tolist() == [pytest.approx(0.2)]
    assert (ev_f["km_m"].iloc[0], ev_r["km_m"].iloc[0]) == (120.0, 109.5)
    df, dr = json.loads(ev_f["detail"].iloc[0]), json.loads(ev_r["detail"].iloc[0])
    assert df["other_unit"] == "R" and dr["other_unit"] == "F"
    assert df["t_to"] == pytest.approx(0.3) and df["cycles"] == 2
    assert (df["cycles_beyond_margins"], df["cycles_on_other_tracks"]) == (1, 1)
    assert (df["difference_m"], dr["difference_m"], df["bound_m"]) == (10.5, -10.5, 10.0)
    assert (df["km_at_worst_m"], df["other_km_at_worst_m"]) == (120.0, 109.5)
    assert (df["track_id"], df["other_track_id"]) == ("A", "A")
    merged = with_events(pd.concat([ev_f.assign(t=0.25)] * 2, ignore_index=True), ev_f)
    assert merged["t"].tolist() == pytest.approx([0.2, 0.25, 0.25])


_STATES = st.sampled_from(["determined", "ambiguous", "uncertain", "undetermined"])


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            _STATES, _STATES, st.floats(-50, 50), st.floats(0, 20), st.floats(0, 20), st.sampled_from(["A", "B"])
        ),
        min_size=1,
        max_size=40,
    )
)
def test_one_event_per_span_in_each_unit(rows: list[tuple[str, str, float, float, float, str]]) -> None:
    """Any two units' positions: each unit gets one ``units_disagree`` event per disagreement
    span of the summary, at its start, the worst |difference| beyond the bound unless the span
    is a track disagreement only, and the two units' differences of opposite sign."""
    n = len(rows)
    t = np.round(np.arange(n) * 0.1, 1)
    f = pd.DataFrame({"t": t, "km_m": 1000.0, "margin_m": [r[3] for r in rows], "state": [r[0] for r in rows],
                      "track_id": "A"})  # fmt: skip
    r = pd.DataFrame({"t": t, "km_m": [1000.0 + x[2] for x in rows], "margin_m": [x[4] for x in rows],
                      "state": [x[1] for x in rows], "track_id": [x[5] for x in rows]})  # fmt: skip
    frame, summary = compare_units(f, r)
    ev = {u: disagreement_events(frame, u) for u in "FR"}
    for u in "FR":
        assert ev[u]["t"].tolist() == [span[0] for span in summary["disagreements"]]
    for df, dr in zip(ev["F"]["detail"], ev["R"]["detail"], strict=True):
        a, b = json.loads(df), json.loads(dr)
        assert a["t_to"] == b["t_to"] and a["cycles"] == b["cycles"]
        if a["cycles_beyond_margins"]:
            # the detail is written to the event's resolution: a difference beyond its bound by
            # less than that (1 nm beyond a zero margin) reads equal to it
            assert abs(a["difference_m"]) >= a["bound_m"] and a["difference_m"] == -b["difference_m"]


def _turnback(net_db: Path, folder: Path, **cab_r: float) -> Path:
    net = read_network(net_db)
    over = dict(network_sample_scenarios(net)["sim-net-turnback"])
    over["cab_r"] = {"sensors": True, **cab_r}
    streams, meta = simulate_run(net, scenario_from_dict(over, source="test"))
    return write_run(folder, meta, streams)


def _both(run: Path, db: Path, out: Path, *extra: str) -> tuple[dict, dict[str, pd.DataFrame], dict[str, dict]]:
    res = CliRunner().invoke(app, ["run", str(run), "--db", str(db), "--out", str(out), "--unit", "both", *extra])
    assert res.exit_code == 0, res.output
    events = {u: pd.read_parquet(out / u / "events.parquet") for u in "FR"}
    summaries = {u: json.loads((out / u / "summary.json").read_text(encoding="utf-8")) for u in "FR"}
    return json.loads((out / "units.json").read_text(encoding="utf-8")), events, summaries


def test_units_on_their_own_sensors_agree_on_a_turnback(sample_network_db: Path, tmp_path: Path) -> None:
    """The seeded sample turnback with the R cab's own IMU, tacho and GPS: both units within
    their margins of the truth, within the sum of margins of each other, no event."""
    run = _turnback(sample_network_db, tmp_path / "tb")
    cmp, events, summaries = _both(run, sample_network_db, tmp_path / "out")
    assert cmp["unit_r"]["streams"] == {"imu": "imu_r", "tacho": "tacho_r", "gps": "gps_r"}
    assert cmp["cycles_compared"] > 2500
    assert 0.5 < cmp["max_abs_difference_m"] < 10.0  # independent sensors: not the same numbers
    assert cmp["cycles_beyond_margins"] == 0 and cmp["cycles_on_other_tracks"] == 0 and cmp["disagreements"] == []
    for u in "FR":
        assert not (events[u]["type"] == EventType.UNITS_DISAGREE.value).any()
        assert summaries[u]["truth"]["within_margin_share"] == 1.0
        assert summaries[u]["truth"]["wrong_track_cycles"] == 0
    # --unit R alone: the same unit R, and it says what it read
    out_r = tmp_path / "out-r"
    res = CliRunner().invoke(app, ["run", str(run), "--db", str(sample_network_db), "--out", str(out_r), "--unit", "R"])
    assert res.exit_code == 0, res.output
    assert "Unit R read the R cab's own imu_r, tacho_r, gps_r." in res.output
    pd.testing.assert_frame_equal(
        pd.read_parquet(out_r / "positions.parquet"), pd.read_parquet(tmp_path / "out" / "R" / "positions.parquet")
    )


def test_an_uncorrected_r_wheel_raises_disagreement_events(sample_network_db: Path, tmp_path: Path) -> None:
    """The R axle's wheel 10 % larger than run.json says, with neither the wheel rescale nor the
    balise interval check's widening (``[margin] wheel_rescale = false``, ``scale_check_pct =
    50``): unit R's distance runs ~9 % short, beyond its 2 % margin, so the units part — the
    events are in both outputs, and the truth shows unit R is the one that is wrong."""
    run = _turnback(sample_network_db, tmp_path / "tb", wheel_error_pct=10.0)
    config = tmp_path / "no-correction.toml"
    config.write_text("[margin]\nwheel_rescale = false\nscale_check_pct = 50.0\n", encoding="utf-8")
    cmp, events, summaries = _both(run, sample_network_db, tmp_path / "out", "--config", str(config))
    assert cmp["cycles_beyond_margins"] > 100 and cmp["disagreements"]
    for u in "FR":
        mine = events[u][events[u]["type"] == EventType.UNITS_DISAGREE.value]
        assert len(mine) == len(cmp["disagreements"])
        assert mine["t"].tolist() == [span[0] for span in cmp["disagreements"]]
        assert events[u]["t"].is_monotonic_increasing
    details = [json.loads(d) for d in events["R"].loc[events["R"]["type"] == "units_disagree", "detail"]]
    assert all(abs(d["difference_m"]) > d["bound_m"] for d in details if d["cycles_beyond_margins"])
    assert summaries["F"]["truth"]["within_margin_share"] == 1.0
    assert summaries["R"]["truth"]["within_margin_share"] < 0.8
