"""An I2 telegram read without its I1 as track evidence (fieldlogs/pipeline/aids/track_balise.py).

Crossover network (tests/data/networks): D1 and U1 run side by side 4 m apart from km 0; the
position starts ambiguous between them at km 100, 10 m/s toward km 300 (kp = +1 on both), margin
1 m + 2 % of the travel. The DB gets one initial pair by hand on track U at km 150 (I2)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from fieldlogs.pipeline.aid import Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.aids.balise import BaliseDb, telegram_rows
from fieldlogs.pipeline.aids.topology import TopologyAid, with_hyps
from fieldlogs.pipeline.aids.track_balise import TrackBaliseAid
from fieldlogs.pipeline.config import BaliseConfig
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.pipeline.types import Fix, Hypothesis
from schemas.enums import EventType, FixSource, PositionState
from tests.fieldlogs.pipeline.network_cases import MARGIN, net, travel

DB = BaliseDb(
    {
        ("9003", "01", "U"): {
            "I1": {"balise_id": "U-I1", "km_actual_m": 145.0},
            "I2": {"balise_id": "U-I2", "km_actual_m": 150.0},
        }
    },
    {},
    {"9003"},
)


class _Ambiguous(StaticAid):
    """D1 and U1 at pos 100 from t = 0, uncertainty 1 m."""

    name = "start"
    priority = Priority.TELEGRAM

    def observations(self) -> list[Observation]:
        return [Observation(0.0)]

    def observe(self, obs: Observation, view: object) -> Outcome:
        nan = float("nan")
        seed = Fix(0.0, 0.0, 0.0, nan, nan, "", "", 1, FixSource.BALISE, 1.0)
        hyps = [Hypothesis("D1", 100.0, 1, hid=1), Hypothesis("U1", 100.0, 1, hid=2)]
        return Outcome([], with_hyps(seed, hyps, 0.0, 0.0, track_lines(net("crossover"))))


def _run(t_read: float, track: str = "U") -> Solution:
    n = net("crossover")
    lines = track_lines(n)
    tel = pd.DataFrame({"t": [t_read], "kind": ["I2"], "station_code": ["01"], "track": [track]})
    aid = TrackBaliseAid(DB, lines, BaliseConfig(), MARGIN, telegram_rows(tel))
    aids = [_Ambiguous(), TopologyAid(lines, MARGIN), aid]
    return run_aids(travel(n, np.full(120, 10.0)), aids, MARGIN)  # type: ignore[list-item]


def _at(sol: Solution, t: float) -> pd.Series:
    p = sol.positions
    return p[p["t"].sub(t).abs() < 1e-6].iloc[0]


def test_an_i2_without_its_i1_tells_the_track() -> None:
    # read at t = 5 s: both readers at pos 150 (100 + 50), the U balise there — U1 holds it
    sol = _run(5.0)
    res = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    assert len(res) == 1 and res[0].t == 5.0
    assert res[0].detail["evidence"] == "balise" and res[0].detail["track_id"] == "U1"
    assert res[0].detail["balise_id"] == "U-I2" and sorted(res[0].detail["candidates"]) == ["D1", "U1"]
    assert _at(sol, 4.9)["state"] == PositionState.AMBIGUOUS.value
    after = _at(sol, 6.0)
    assert after["state"] == PositionState.DETERMINED.value and after["track_id"] == "U1"
    assert after["pos_m"] == pytest.approx(160.0, abs=1e-3)  # placed at the balise, 10 m since


def test_a_read_no_candidate_holds_changes_nothing() -> None:
    # at t = 9 s the candidates are at pos 190, 40 m past the balise (margin 1 + 1.8 m, reader
    # latency 0.1 s·10 m/s): the read is not theirs — and a D telegram has no pair in the DB
    for sol in (_run(9.0), _run(5.0, "D")):
        assert not [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
        assert _at(sol, 10.0)["state"] == PositionState.AMBIGUOUS.value
        assert {c["track_id"] for c in json.loads(str(_at(sol, 10.0)["candidates"]))} == {"D1", "U1"}
