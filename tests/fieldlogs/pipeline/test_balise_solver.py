"""Balise state machine (SPEC §5.2) and the solver's dead reckoning, hand-computed.

A tiny network: line 0900, stations with pairs on D and U (fieldlogs.simulate.networks.synthetic), a train
with a known travel profile; telegrams are written by hand.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dbtools.gis.geometry import Projector
from fieldlogs.pipeline.aids.balise import BaliseDb
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.types import Odometry, SlipEpisode
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from tests.fieldlogs.pipeline.engine_cases import solve

CFG = PipelineConfig()


@pytest.fixture(scope="module")
def net():
    return build_network([demo_line()], Projector(9))


def cycles_const(v: float, seconds: float, cab: np.ndarray | None = None, scale: float = 1.0):
    """Cycles and odometry at constant speed; ``scale`` = measured/true distance."""
    t = np.arange(0.0, seconds + 1e-9, 0.1)
    d = v * t * scale
    n = t.size
    c = Cycles(
        t,
        d,
        d,
        np.full(n, v * scale),
        {k: np.zeros(n) for k in ("ax", "ay", "az", "wx", "wy", "wz")},
        np.ones(n, dtype=np.int8) if cab is None else cab,
        np.ones(n, dtype=np.int8),
        True,
        True,
    )
    odo = Odometry(d, np.full(n, v * scale), np.zeros(n, dtype=bool), np.zeros(n))
    return c, odo


def tel(rows: list[tuple]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=["t", "kind", "line_code", "station_code", "track", "signal_type"])


def balise_km(net, bid: str) -> float:
    b = net.balises.set_index("balise_id")
    return float(b.loc[bid, "km_actual_m"])


def run(net, telegrams, c, odo):
    return solve(c, odo, telegrams, BaliseDb.from_network(net), CFG)


def test_undetermined_until_pair_then_counts_up_on_d(net) -> None:
    c, odo = cycles_const(10.0, 60.0)
    km_i2 = balise_km(net, "0900-01-D-I2")
    sol = run(net, tel([(10.0, "I1", "0900", None, None, None), (10.5, "I2", None, "01", "D", None)]), c, odo)
    pos = sol.positions
    assert (pos.loc[pos.t < 10.5, "state"] == "undetermined").all()
    assert pos.loc[pos.t < 10.5, "km_m"].isna().all()
    row = pos.loc[np.isclose(pos.t, 20.5)].iloc[0]
    assert row.state == "determined" and row.track == "D" and row.line_code == "0900"
    assert row.km_m == pytest.approx(km_i2 + 100.0)  # 10 s at 10 m/s after I2, km counting up
    assert [e.type for e in sol.events] == ["initial_position"]


def test_u_telegram_counts_down_and_reversal_flips(net) -> None:
    # run 10 m/s, stand still from 29 s to 31 s, change ends at 30 s, run back
    c, odo = cycles_const(10.0, 60.0)
    t = c.t
    d = np.where(t < 29.0, 10.0 * t, np.where(t < 31.0, 290.0, 290.0 + 10.0 * (t - 31.0)))
    c.d_pulse[:] = d
    odo.d[:] = d
    c.cab[t >= 30.0 - 1e-9] = -1
    km_i2 = balise_km(net, "0900-01-U-I2")
    sol = run(net, tel([(10.0, "I1", "0900", None, None, None), (10.5, "I2", None, "01", "U", None)]), c, odo)
    pos = sol.positions.set_index(sol.positions.t.round(1))
    assert pos.loc[20.5, "km_m"] == pytest.approx(km_i2 - 100.0)
    # 18.5 s down to the stop (185 m), then 9 s back up (90 m)
    assert pos.loc[40.0, "km_m"] == pytest.approx(km_i2 - 185.0 + 90.0)


def test_reverse_order_pair_ignored_and_unknown_codes_keep_state(net) -> None:
    c, odo = cycles_const(10.0, 60.0)
    sol = run(
        net,
        tel(
            [
                (5.0, "I2", None, "01", "D", None),
                (5.5, "I1", "0900", None, None, None),  # reverse order
                (10.0, "I1", "9999", None, None, None),
                (10.5, "I2", None, "01", "D", None),  # unknown line
                (20.0, "I1", "0900", None, None, None),
                (20.5, "I2", None, "77", "D", None),  # unknown station
            ]
        ),
        c,
        odo,
    )
    types = [e.type for e in sol.events]
    assert types == ["pair_ignored", "balise_anomaly", "pair_ignored", "balise_anomaly"]
    assert (sol.positions.state == "undetermined").all()


def test_pair_farther_than_10_m_is_ignored(net) -> None:
    c, odo = cycles_const(10.0, 30.0)
    sol = run(net, tel([(10.0, "I1", "0900", None, None, None), (11.2, "I2", None, "01", "D", None)]), c, odo)
    assert sol.events[0].type == "pair_ignored" and "12.0 m" in sol.events[0].detail["reason"]


def test_c_balise_correction_amount_and_percentage(net) -> None:
    """Wheel reads 0.5 % long: correction amount = +0.5 % of the distance since the pair."""
    b = net.balises
    c_row = b[(b.kind == "C") & (b.track == "D") & (b.station_code == "01")].sort_values("km_actual_m").iloc[0]
    km_i1, km_i2 = balise_km(net, "0900-01-D-I1"), balise_km(net, "0900-01-D-I2")
    v, scale = 10.0, 1.005
    t_i1 = 10.0
    t_i2 = t_i1 + (km_i2 - km_i1) / v
    t_c = t_i1 + (float(c_row.km_actual_m) - km_i1) / v
    c, odo = cycles_const(v, t_c + 20.0, scale=scale)
    sol = run(
        net,
        tel(
            [
                (t_i1, "I1", "0900", None, None, None),
                (t_i2, "I2", None, "01", "D", None),
                (t_c, "C", None, None, None, str(c_row.signal_type)),
            ]
        ),
        c,
        odo,
    )
    corr = [e for e in sol.events if e.type == "balise_correction"]
    assert len(corr) == 1
    dist = float(c_row.km_actual_m) - km_i2
    assert corr[0].correction_m == pytest.approx(0.005 * dist, rel=1e-6)
    # distance since the pair as the onboard unit measured it (0.5 % long)
    assert corr[0].correction_pct == pytest.approx(0.5 / 1.005, abs=1e-6)
    after = sol.positions.loc[sol.positions.t > t_c + 1.0].iloc[0]
    assert after.km_m == pytest.approx(float(c_row.km_actual_m) + v * scale * (after.t - t_c), abs=1e-6)


def test_c_balise_outside_window_is_an_anomaly(net) -> None:
    b = net.balises
    c_row = b[(b.kind == "C") & (b.track == "D") & (b.station_code == "01")].sort_values("km_actual_m").iloc[0]
    c, odo = cycles_const(10.0, 40.0)
    sol = run(
        net,
        tel(
            [
                (1.0, "I1", "0900", None, None, None),
                (1.5, "I2", None, "01", "D", None),
                (2.0, "C", None, None, None, str(c_row.signal_type)),
            ]
        ),
        c,
        odo,
    )  # far too early
    assert sol.events[-1].type == "balise_anomaly"
    assert "window" in sol.events[-1].detail["reason"]


def test_margin_grows_2_percent_and_failsafe_makes_uncertain(net) -> None:
    c, odo = cycles_const(10.0, 60.0)
    ep = SlipEpisode("slip", 39.0, 30.0, 40.0, 300, 400, 100.0, 100.0, 22.8, False, True,
                     criterion="ta", start_found=True, theta0_rad=0.0, v0_mps=10.0)  # fmt: skip
    odo.episodes.append(ep)
    sol = run(net, tel([(10.0, "I1", "0900", None, None, None), (10.5, "I2", None, "01", "D", None)]), c, odo)
    pos = sol.positions.set_index(sol.positions.t.round(1))
    # the fix holds its latency budget at the telegram's 10 m/s: 1 m + 0.1 s × 10 m/s = 2 m
    u_fix = CFG.balise.fix_uncertainty_m + CFG.balise.latency_budget_s * 10.0
    assert pos.loc[30.5, "margin_m"] == pytest.approx(u_fix + 0.02 * 200.0)
    assert pos.loc[39.9, "state"] == "determined"
    assert pos.loc[40.0, "state"] == "uncertain"
    assert pos.loc[50.0, "margin_m"] > u_fix + 0.02 * 395.0
    assert "failsafe" in [e.type for e in sol.events]


def test_gps_decision_while_standing_initialises_once_the_km_moves(net) -> None:
    """A decision with no km direction (vehicle standing) does not set a position; the first
    later trusted fix on that track 10 m or more away does, with the direction it moved in."""
    from fieldlogs.pipeline.types import GpsAnalysis, TrackDecision

    c, odo = cycles_const(10.0, 60.0)
    t = np.arange(0.0, 61.0)
    fixes = pd.DataFrame(
        {
            "t": t,
            "trusted": t >= 5,
            "decided_track": "U",
            "track": "U",
            "km_m": np.where(t < 20, 5000.0, 5000.0 - 10.0 * (t - 20)),
        }
    )
    dec = TrackDecision(15.0, "0900", "U", 5000.0, 0, {"n_fixes": 10})
    sol = solve(c, odo, None, BaliseDb.from_network(net), CFG, gps=GpsAnalysis(fixes, [dec], []))
    assert [e.type for e in sol.events] == ["track_decision", "initial_position_gps"]
    init = sol.events[1]
    assert init.t == 21.0 and init.km_m == 4990.0
    pos = sol.positions.set_index(sol.positions.t.round(1))
    assert pos.loc[20.9, "state"] == "undetermined"
    assert pos.loc[31.0, "km_m"] == pytest.approx(4990.0 - 100.0)  # km decreasing, as the fixes moved
    assert pos.loc[31.0, "last_fix_source"] == "gps"
