"""Vehicle geometry in the pipeline (issue 16): a balise is read at the reader, a GPS fix is
taken at its antenna, and the vehicle occupies [tail, head] — hand-computed."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dbtools.gis.geometry import Projector
from fieldlogs.pipeline.aids.balise import BaliseAid, BaliseDb, telegram_rows
from fieldlogs.pipeline.aids.gps import GpsAid
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.geometry import VehicleGeometry
from fieldlogs.pipeline.types import GpsAnalysis, TrackDecision
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from tests.fieldlogs.pipeline.test_balise_solver import balise_km, cycles_const, tel

CFG = PipelineConfig()
PAIR = [(10.0, "I1", "0900", None, None, None), (10.5, "I2", None, "01", "D", None)]


@pytest.fixture(scope="module")
def net():  # type: ignore[no-untyped-def]
    return build_network([demo_line()], Projector(9))


def _run(net, cab_sign: int, reader_x: float, geometry: VehicleGeometry | None = None):  # type: ignore[no-untyped-def]
    c, odo = cycles_const(10.0, 40.0, cab=np.full(401, cab_sign, dtype=np.int8))
    aid = BaliseAid(BaliseDb.from_network(net), CFG.balise, telegram_rows(tel(PAIR)), reader_x_m=reader_x)
    return run_aids(Travel.of(c, odo), [aid], CFG.margin, geometry)


@pytest.mark.parametrize(("cab", "expected_offset"), [(1, -5.0), (-1, +5.0)])
def test_balise_read_at_the_reader(net, cab: int, expected_offset: float) -> None:  # type: ignore[no-untyped-def]
    """Reader 5 m toward the F end. Running F on D (k = +1) the reader leads: the reference
    point is 5 m before the balise; with the cab reversed (k = −1, F end toward lower km)
    the reader trails on the km axis: the reference point is 5 m beyond it."""
    km_i2 = balise_km(net, "0900-01-D-I2")
    sol = _run(net, cab, 5.0)
    pos = sol.positions.set_index(sol.positions.t.round(1))
    km_at_pair = float(pos.loc[10.5, "km_m"])
    assert km_at_pair == pytest.approx(km_i2 + expected_offset)
    assert sol.events[0].km_m == pytest.approx(km_i2)  # the event names the balise's own km


def test_without_geometry_nothing_moves(net) -> None:  # type: ignore[no-untyped-def]
    a = _run(net, 1, 0.0).positions
    b = _run(net, 1, 0.0, VehicleGeometry()).positions
    assert a["km_m"].equals(b["km_m"])
    assert a["km_head_m"].isna().all() and a["km_tail_m"].isna().all()


def test_head_and_tail_follow_the_running_direction(net) -> None:  # type: ignore[no-untyped-def]
    geom = VehicleGeometry(front_x_m=12.0, length_m=20.0)  # F end 12 m ahead, R end 8 m behind
    for cab, head_off, tail_off in ((1, 12.0, -8.0), (-1, 8.0, -12.0)):
        pos = _run(net, cab, 0.0, geom).positions
        row = pos.loc[np.isclose(pos.t, 30.0)].iloc[0]
        # cab F: k = +1, F end leads at km + 12; cab R: k = −1, the R end (km − k·8 = km + 8) leads
        assert row.km_head_m == pytest.approx(row.km_m + head_off)
        assert row.km_tail_m == pytest.approx(row.km_m + tail_off)


def test_gps_initial_position_is_taken_at_the_antenna(net) -> None:  # type: ignore[no-untyped-def]
    c, odo = cycles_const(10.0, 40.0)
    t = np.arange(0.0, 41.0)
    fixes = pd.DataFrame({"t": t, "trusted": True, "decided_track": "D", "track": "D", "km_m": 5000.0 + 10.0 * t})
    dec = TrackDecision(20.0, "0900", "D", 5200.0, 1, {"n_fixes": 15})
    for antenna_x in (0.0, 7.5):
        aid = GpsAid(GpsAnalysis(fixes, [dec], []), CFG.gps, antenna_x_m=antenna_x)
        sol = run_aids(Travel.of(c, odo), [aid], CFG.margin)
        pos = sol.positions.set_index(sol.positions.t.round(1))
        assert pos.loc[30.0, "km_m"] == pytest.approx(5200.0 + 100.0 - antenna_x)


def test_geometry_from_the_vehicle_block() -> None:
    g = VehicleGeometry.of(
        {
            "front_x_m": 10.0,
            "length_m": 20.0,
            "balise_reader": {"x_m": 3.0, "y_m": 0.0},
            "antennas": [{"id": "a", "receiver": "r1", "x_m": -4.0, "y_m": 0.0, "z_m": 3.8}],
        }
    )
    assert (g.reader_x_m, g.gps_antenna_x_m, g.front_x_m, g.length_m) == (3.0, -4.0, 10.0, 20.0)
    assert VehicleGeometry.of(None) == VehicleGeometry()
