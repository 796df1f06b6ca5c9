"""Evidence after a facing switch on tracks off a line (issue 31: every facing switch resolved):
a balise group standing on a crossover, placed by the crossover's own track points."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from fieldlogs.pipeline.aids.balise_group import BaliseGroupAid, balise_pos, group_table
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.config import BaliseConfig
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.hypotheses import track_lines
from schemas.enums import EventType
from tests.fieldlogs.pipeline.network_cases import MARGIN, Start, net, travel


def test_balise_pos_on_a_crossover_by_its_track_points_hand_computed() -> None:
    # X1's points (pos, km): (0, 300), (20, 319.967), (40, 339.868), (60.166, 360); a balise at
    # km 328 lies between the 2nd and 3rd: pos = 20 + (328 − 319.967)/(339.868 − 319.967)·20
    # = 20 + 8.033/19.901·20 = 28.0730
    lines = track_lines(net("crossover"))
    assert balise_pos(lines["X1"], 328.0) == pytest.approx(28.0730, abs=1e-3)
    assert balise_pos(lines["X1"], 300.5) == pytest.approx(0.5 * 20.0 / 19.967, abs=1e-6)
    assert balise_pos(lines["X1"], 360.9) == pytest.approx(60.166)  # within 1 m of the range: clamped
    assert math.isnan(balise_pos(lines["X1"], 361.5))  # beyond: not on this track
    # a track along the line keeps its line's metric (rail length; D2 begins at km 300, 20 m on)
    assert (
        balise_pos(lines["D2"], 320.0) == pytest.approx(lines["D2"].pos_of_km(320.0)) == pytest.approx(20.0, abs=1e-3)
    )


def test_balise_group_on_the_crossover_resolves_the_split() -> None:
    # from D1 km 200 at 10 m/s: W1's toe (km 300) splits the estimate into D2 and X1; group 3
    # stands on X1 at km 328 (pos 28.073, above): read at t = 13 s it keeps X1 alone, placed at
    # the balise, and from then on the position is determined on X1 and dead-reckoned along it
    n = net("crossover")
    rows = [{"t": 13.0, "kind": "G", "nid_c": 230, "nid_bg": 3, "n_pig": 0}]
    aid = BaliseGroupAid(group_table(n), track_lines(n), BaliseConfig(), pd.DataFrame(rows))
    sol = run_aids(
        travel(n, np.full(160, 10.0)), [Start("9003", "D", 200.0, 1), TopologyAid(track_lines(n), MARGIN), aid], MARGIN
    )
    res = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    assert len(res) == 1 and res[0].detail["evidence"] == "balise_group" and res[0].detail["track_id"] == "X1"
    assert sorted(res[0].detail["candidates"]) == ["D2", "X1"]
    assert res[0].detail["after_switch_m"] == pytest.approx(30.0, abs=1.5)
    p = sol.positions
    after = p[(p["t"] >= 13.0) & (p["t"] <= 15.0)]
    assert (after["state"] == "determined").all() and (after["track_id"] == "X1").all()
    assert after["pos_m"].iloc[10] == pytest.approx(28.073 + 10.0, abs=0.05)  # 1 s later
