"""The survey's headline on a small seeded case (the bench's targets, not timed): the
bundled sample network with a displaced balise, a missing one, two unpowered ones and a
missing curve, eight simulated runs (``survey_data``)."""

from __future__ import annotations

import numpy as np
import pytest

from fieldlogs.survey.features import db_features
from fieldlogs.survey.result import SurveyReport
from fieldlogs.survey.runner import survey
from tests.fieldlogs.survey.survey_data import (
    MOVED,
    REMOVED_BALISE,
    REMOVED_FEATURE,
    UNPOWERED,
    SurveyData,
    survey_data,
)


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> SurveyData:
    return survey_data(tmp_path_factory)


@pytest.fixture(scope="module")
def report(data: SurveyData) -> SurveyReport:
    return survey([data.logs], data.db, workers=1)


def test_the_displaced_balise_is_moved_by_its_residual(report: SurveyReport) -> None:
    b = report.balises.set_index("balise_id")
    for bid, dx in MOVED.items():
        assert b.loc[bid, "status"] == "moved"
        assert b.loc[bid, "residual_m"] == pytest.approx(dx, abs=0.5)
        assert b.loc[bid, "ci95_m"] < 0.5
    others = b.drop(index=[*MOVED, *UNPOWERED])
    assert not others["status"].isin(["moved", "missed"]).any(), others[others["status"] != "ok"]


def test_unpowered_balises_are_missed_with_their_passes(report: SurveyReport) -> None:
    b = report.balises.set_index("balise_id")
    for bid in UNPOWERED:
        assert b.loc[bid, "status"] == "missed"
        assert b.loc[bid, "passes"] == 4 and b.loc[bid, "reads"] == 0
    assert sorted(report.missed["balise_id"].unique()) == sorted(UNPOWERED)
    assert len(report.missed) == 8 and report.missed["time"].str.startswith("2026-02-0").all()


def test_the_balise_missing_from_the_db_is_a_confirmed_candidate(report: SurveyReport, data: SurveyData) -> None:
    true_km = float(data.truth.balises.set_index("balise_id").loc[REMOVED_BALISE, "km_actual_m"])
    c = report.candidates[report.candidates["confirmed"]]
    assert len(c) == 1
    assert c["km_m"].iloc[0] == pytest.approx(true_km, abs=0.5)
    assert c["runs"].iloc[0] == 4 and c["tel_signal_type"].iloc[0] == "home"


def test_the_missing_curve_is_new_within_10_m_and_10_percent(report: SurveyReport, data: SurveyData) -> None:
    truth = db_features(data.truth.feature_points).set_index(["line_code", "track", "feature_id"]).loc[REMOVED_FEATURE]
    f = report.features
    new = f[f["status"] == "new"]
    assert len(new) == 1
    assert new["exit_km_m"].iloc[0] == pytest.approx(truth["exit_km_m"], abs=10.0)
    assert new["radius_m"].iloc[0] == pytest.approx(truth["radius_m"], rel=0.10)
    assert not f["status"].isin(["moved", "not seen"]).any()


def test_wheel_diameters_within_a_tenth_of_a_percent(report: SurveyReport, data: SurveyData) -> None:
    w = report.wheels.set_index("vehicle_id")
    for vid in ("EMU-A", "EMU-B"):
        assert w.loc[vid, "runs_estimated"] >= 3
        assert w.loc[vid, "diameter_m"] / data.true_wheel(vid) - 1 == pytest.approx(0.0, abs=0.001)
    assert w.loc["EMU-B", "status"] == "alert"  # 0.35 % worn, alert beyond 0.3 %
    assert w.loc["EMU-A", "status"] == "ok"


def test_the_proposal_changes_only_the_flagged_items(report: SurveyReport) -> None:
    ch = report.changes
    assert set(ch["action"]) == {"move", "add"}
    assert ch["applied"].all()
    assert sorted(ch.loc[ch["action"] == "move", "key"]) == sorted(MOVED)
    assert report.proposed is not None
    before = report.network.balises.set_index("balise_id")
    after = report.proposed.balises.set_index("balise_id")
    common = before.index.intersection(after.index).drop(list(MOVED))
    assert (before.loc[common, "km_actual_m"] == after.loc[common, "km_actual_m"]).all()
    moved = after.loc[list(MOVED), "km_actual_m"] - before.loc[list(MOVED), "km_actual_m"]
    assert np.allclose(moved, [-v for v in MOVED.values()], atol=0.5)
    assert len(after) == len(before) + 1  # the candidate


def test_the_truth_db_shows_nothing_but_the_unpowered_balises(data: SurveyData) -> None:
    rep = survey([data.logs], data.truth_db, workers=1)
    flagged = rep.balises[rep.balises["status"].isin(["moved", "missed"])]
    assert sorted(flagged["balise_id"]) == sorted(UNPOWERED)
    assert (flagged["status"] == "missed").all()
    assert not rep.features["status"].isin(["moved", "new", "not seen"]).any()
    assert rep.candidates.empty or not rep.candidates["confirmed"].any()
