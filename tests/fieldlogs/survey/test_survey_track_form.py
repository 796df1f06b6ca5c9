"""Curves a track along a line holds per track (``track_feature_points``) compared and
proposed on the line's km (fieldlogs/survey/trackform.py): the bundled sample's station
loop 0420-4 (line 0420, local track 4; km 20800 at its begin, increasing with pos).

Hand computation from its track points (pos 40 ↔ km 20839.867, pos 60 ↔ 20859.809, pos 80
↔ 20879.809): F1's entry row pos 45.208 lies at km 20839.867 + 5.208/20 · 19.942 =
20845.060, its exit row pos 65.142 at 20859.809 + 5.142 = 20864.951.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.database import read_network
from dbtools.network import Network
from dbtools.validate import validate_network
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.featurecompare import compare
from fieldlogs.survey.features import CURVE_COLUMNS, TrackCurves
from fieldlogs.survey.propose import _feature_changes, apply_changes
from fieldlogs.survey.trackform import along_line, km_features, pos_rows
from schemas.enums import Severity

CFG = SurveyConfig(min_curve_m=10.0)


@pytest.fixture(scope="module")
def net(sample_network_db) -> Network:  # type: ignore[no-untyped-def]
    return read_network(sample_network_db)


def test_the_loops_and_the_branch_hold_their_curves_per_track(net: Network) -> None:
    assert along_line(net) == {"0420-3": ("0420", "3"), "0420-4": ("0420", "4"), "0421-S1": ("0421", "S")}
    f1 = km_features(net).query("track_id == '0420-4' and feature_id == 'F1'").set_index("seq")
    assert f1.loc[3, "km_m"] == pytest.approx(20845.060, abs=1e-3)
    assert f1.loc[4, "km_m"] == pytest.approx(20864.951, abs=1e-3)
    assert (f1["line_code"] == "0420").all() and (f1["track"] == "4").all() and f1.loc[3, "attribute"] == "left"


def _curve(cid: str, entry: float, exit_: float, attribute: str = "left") -> dict[str, object]:
    return {
        "line_code": "0420",
        "track": "4",
        "curve_id": cid,
        "attribute": attribute,
        "radius_m": 200.0,
        "entry_km_m": entry,
        "exit_km_m": exit_,
        "passes": 4,
        "entry_ci95_m": 0.3,
        "exit_ci95_m": 0.3,
        "radius_spread": 0.01,
        "transition_start_km_m": entry,
        "transition_end_km_m": exit_,
        "straights_ok": True,
    }


@pytest.fixture(scope="module")
def judged(net: Network) -> tuple[pd.DataFrame, dict]:  # type: ignore[type-arg]
    # the runs see F1 where the DB has it, F2 15 m later, and a new R 200 curve at km 21000
    f2 = km_features(net).query("track_id == '0420-4' and feature_id == 'F2'").set_index("seq")["km_m"]
    curves = pd.DataFrame(
        [
            _curve("0420-4-001", 20845.060, 20864.951),
            _curve("0420-4-002", float(f2[3]) + 15.0, float(f2[4]) + 15.0),
            _curve("0420-4-003", 21000.0, 21020.0, "right"),
        ],
        columns=list(CURVE_COLUMNS),
    )
    surveyed = {("0420", "4"): TrackCurves(curves, pd.DataFrame())}
    return compare(net.feature_points, surveyed, {}, CFG, net, net.track_feature_points), surveyed


def test_compared_with_the_tracks_own_rows_on_the_lines_km(judged) -> None:  # type: ignore[no-untyped-def]
    f = judged[0]
    mine = f[f["track_id"] == "0420-4"].set_index("curve_id")
    assert mine.loc["0420-4-001", ["feature_id", "status"]].tolist() == ["F1", "ok"]
    assert mine.loc["0420-4-002", ["feature_id", "status"]].tolist() == ["F2", "moved"]
    assert mine.loc["0420-4-003", "status"] == "new"
    assert (mine["db_table"] == "track_feature_points").all()
    assert (f.loc[f["line_code"] == "0420", "db_table"].isin(["feature_points", "track_feature_points"])).all()
    # the line D/U features stay the line's
    assert set(f.loc[f["track_id"].isin(["0420-D1", "0420-U1"]), "db_table"]) == {"feature_points"}


def test_proposed_as_the_tracks_own_rows_by_pos(net: Network, judged) -> None:  # type: ignore[no-untyped-def]
    f, surveyed = judged
    changes = _feature_changes(f, surveyed, net)
    assert {c.table for c in changes} == {"track_feature_points"}
    assert {(c.action, c.key) for c in changes} == {("replace", "F2"), ("add", "S001")}
    proposed = apply_changes(net, changes)
    assert proposed.feature_points.equals(net.feature_points)  # no km rows for a curve held per track
    tfp = proposed.track_feature_points
    f2 = tfp[(tfp["track_id"] == "0420-4") & (tfp["feature_id"] == "F2")].sort_values("seq")
    old = net.track_feature_points
    old2 = old[(old["track_id"] == "0420-4") & (old["feature_id"] == "F2")].sort_values("seq")
    # the entry and exit rows 15 m later along the track (km ≈ pos here: 0.1 m rounding)
    assert f2["pos_m"].to_numpy()[2:4] == pytest.approx(old2["pos_m"].to_numpy()[2:4] + 15.0, abs=0.11)
    new = tfp[(tfp["track_id"] == "0420-4") & (tfp["feature_id"] == "S001")].sort_values("seq")
    assert new["attribute"].tolist()[2] == "right" and np.all(np.diff(new["pos_m"].to_numpy()) >= 0)
    assert not [x for x in validate_network(net) if x.severity == Severity.ERROR]
    errors = {
        (x.rule, x.keys.get("track_id"), x.keys.get("feature_id"))
        for x in validate_network(proposed)
        if x.severity == Severity.ERROR
    }
    # the rows are checked as the track's own: the sample's centreline has no curve where the
    # made-up runs put S001 (nor F2 15 m on), so the proposal's guard would keep them out
    assert errors == {("feature.track_turn", "0420-4", "F2"), ("feature.track_turn", "0420-4", "S001")}


@settings(max_examples=40, deadline=None)
@given(shift=st.floats(0.0, 400.0), reverse=st.booleans())
def test_pos_to_km_and_back(net: Network, shift: float, reverse: bool) -> None:
    # six rows of the loop mapped to km and back are the same rows (0.1 m rounding); read in
    # the other order (a U-like track, km decreasing) they come back reversed and mirrored
    pos = np.array([0.0, 20.0, 30.0, 60.0, 70.0, 90.0]) + shift
    km_pts = net.track_points.query("track_id == '0420-4'")
    k = np.interp(pos, km_pts["pos_m"], km_pts["km_m"])
    attrs = ["straight", "transition", "left", "transition", "straight", "none"]
    rows = [
        {"feature_id": "F9", "km_m": x, "radius_m": 200.0 if i == 2 else 0.0, "attribute": a, "role": None}
        for i, (x, a) in enumerate(zip(k[::-1] if reverse else k, attrs, strict=True))
    ]
    back = pos_rows(rows, "0420-4", net)
    assert [r["pos_m"] for r in back] == pytest.approx(pos.tolist(), abs=0.051)
    assert back[2]["attribute"] == ("right" if reverse else "left") and back[2]["radius_m"] == 200.0
