"""Evidence after a facing switch on tracks off a line (issue 31: every facing switch resolved):
a balise group standing on a crossover, placed by the crossover's own track points."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from dbtools.network import Network
from dbtools.rules.balise_groups import locate
from fieldlogs.pipeline.aids.balise import telegram_rows
from fieldlogs.pipeline.aids.balise_group import BaliseGroupAid, balise_pos, group_table
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.config import BaliseConfig
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import TrackLines, track_lines
from schemas.enums import EventType
from tests.fieldlogs.pipeline.network_cases import MARGIN, Start, net, travel
from tests.fieldlogs.pipeline.test_track_selection_property import DT, Truth, start_on_line, walk


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
    aid = BaliseGroupAid(group_table(n), track_lines(n), BaliseConfig(), rows)
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


def _telegrams(network: Network, lines: TrackLines, truth: Truth, t: np.ndarray) -> pd.DataFrame:
    """A G telegram each time the true position passes a DB balise (placed as the DB's rules and
    the simulator place it, :func:`dbtools.rules.balise_groups.locate`), in time order."""
    tid, pos = locate(network)
    b = network.balises
    rows = []
    track = np.array(truth.track, dtype=object)
    for j in np.flatnonzero(pd.notna(tid) & np.isfinite(pos) & (b["kind"] == "G").to_numpy()):
        on = track == tid[j]
        side = truth.pos >= pos[j]
        hit = np.flatnonzero(on[1:] & on[:-1] & (side[1:] != side[:-1])) + 1
        rows += [
            {
                "t": float(t[i]),
                "kind": "G",
                "nid_c": int(b["nid_c"].iloc[j]),
                "nid_bg": int(b["nid_bg"].iloc[j]),
                "n_pig": int(b["n_pig"].iloc[j]),
            }
            for i in hit
        ]
    return pd.DataFrame(sorted(rows, key=lambda r: r["t"]), columns=["t", "kind", "nid_c", "nid_bg", "n_pig"])


@settings(max_examples=40, deadline=None)
@example(name="crossover", start=0, kp=1, speed=10.0, scale=0.01, branch=[1])  # D1 → X1 (group 3) → U2
@example(name="crossover", start=4, kp=-1, speed=20.0, scale=-0.01, branch=[0, 1])  # U2 → X1 → D1
@given(
    name=st.sampled_from(["crossover", "station4"]),
    start=st.integers(0, 10_000),
    kp=st.sampled_from([1, -1]),
    speed=st.floats(3.0, 25.0),
    scale=st.floats(-0.015, 0.015),
    branch=st.lists(st.integers(0, 1), min_size=1, max_size=4),
)
def test_balise_groups_never_drop_the_true_branch(
    name: str, start: int, kp: int, speed: float, scale: float, branch: list[int]
) -> None:
    # random routes through the crossovers and station tracks (some of them off a line), the
    # odometry's scale error inside the margin's 2 %: every group read keeps the true track
    n, lines, tid, pos0 = start_on_line(name, start)
    tl = lines[tid]
    v = np.full(round(700.0 / speed / DT), speed)
    truth = walk(n, lines, tid, pos0, kp, v, branch)
    m = truth.s.size
    t = np.arange(m) * DT
    tr = Travel(
        t,
        truth.d * (1 + scale),
        truth.s * (1 + scale),
        np.abs(v[:m]),
        np.ones(m, dtype=np.int8),
        np.ones(m, dtype=bool),
        np.zeros(m),
        n,
    )
    aid = BaliseGroupAid(group_table(n), lines, BaliseConfig(), telegram_rows(_telegrams(n, lines, truth, t)))
    start_fix = Start(tl.line_code, tl.track, float(tl.km_of_pos(pos0)), kp * tl.km_sign)
    sol = run_aids(tr, [start_fix, TopologyAid(lines, MARGIN), aid], MARGIN)
    p = sol.positions
    det = (p["state"] == "determined").to_numpy()
    claimed = p["track_id"].fillna("").astype(object).to_numpy()
    assert not (det & (claimed != np.array(truth.track, dtype=object))).any()
    assert EventType.BALISE_ANOMALY not in {e.type for e in sol.events}  # the true track was never dropped
    # each read fixes the position on the true track (on a crossover too: placed by its points)
    reads = np.searchsorted(t, [float(row["t"]) for row in aid.telegrams]) + 1
    assert det[reads[reads < m]].all()
    resolved = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    assert all(e.detail["track_id"] == truth.track[int(np.searchsorted(t, e.t))] for e in resolved)
