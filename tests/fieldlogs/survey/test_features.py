"""Curves on hand-made curvature traces: the pipeline's 20 % rule, located exactly;
comparison with DB features; the six proposed rows."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fieldlogs.pipeline.config import FeatureConfig
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.curvature import Coverage, TrackSamples, mean_profile
from fieldlogs.survey.featurecompare import compare
from fieldlogs.survey.features import Rule, crossing, proposed_rows, sign_runs, survey_track

CFG = SurveyConfig()
RULE = Rule.of(FeatureConfig(), CFG)
TS, LT, ARC, R = 1000.0, 60.0, 200.0, 600.0
ST = TS + 2 * LT + ARC  # end of the exit transition


def kappa_of(km: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """Straight – clothoid – arc – clothoid – straight (κ linear in the transitions)."""
    up = np.clip((km - TS) / LT, 0.0, 1.0)
    down = np.clip((ST - km) / LT, 0.0, 1.0)
    return sign * np.minimum(up, down) / R


def samples(n_pass: int = 4, sign: float = 1.0, step: float = 2.5) -> TrackSamples:
    parts = []
    for p in range(n_pass):
        km = np.arange(TS - 300.0 + 0.7 * p, ST + 300.0, step)
        parts.append((np.full(km.size, p, dtype=np.int64), km, kappa_of(km, sign)))
    pid = np.concatenate([a for a, _, _ in parts])
    km = np.concatenate([b for _, b, _ in parts])
    k = np.concatenate([c for _, _, c in parts])
    order = np.lexsort((pid, km))
    return TrackSamples(pid[order], km[order], k[order])


def test_crossing_interpolates_linearly() -> None:
    km = np.array([0.0, 10.0])
    k = np.array([0.0, 2.0])
    assert crossing(km, k, 0, 1, 0.5, 1) == pytest.approx(2.5)
    assert crossing(km, -k, 0, 1, 0.5, -1) == pytest.approx(2.5)


def test_sign_runs_merge_chatter_closer_than_the_merge_distance() -> None:
    km = np.arange(10.0)
    k = np.array([0, 1, 1, 0, 1, 1, 0, 0, 0, 1], dtype=float)
    assert sign_runs(km, k, 0.5, 2.5) == [(1, 5, 1), (9, 9, 1)]
    assert sign_runs(km, -k, 0.5, 0.0) == [(1, 2, -1), (4, 5, -1), (9, 9, -1)]


def test_a_curve_is_located_by_its_lower_limit_crossings() -> None:
    tc = survey_track(("0001", "D"), samples(), RULE)
    assert len(tc.curves) == 1
    c = tc.curves.iloc[0]
    lower = 1.0 - FeatureConfig().tolerance  # κ = 0.8/R at 0.8 of the transition
    assert c["entry_km_m"] == pytest.approx(TS + lower * LT, abs=0.05)
    assert c["exit_km_m"] == pytest.approx(ST - lower * LT, abs=0.05)
    assert c["radius_m"] == pytest.approx(R, rel=1e-6)
    assert c["attribute"] == "left"
    assert c["passes"] == 4
    assert c["transition_start_km_m"] == pytest.approx(TS, abs=1.0)
    assert c["transition_end_km_m"] == pytest.approx(ST, abs=1.0)
    assert bool(c["straights_ok"])


def test_on_an_up_track_entry_and_exit_follow_the_running_direction() -> None:
    tc = survey_track(("0001", "U"), samples(sign=-1.0), RULE)
    c = tc.curves.iloc[0]
    assert c["attribute"] == "right"
    assert c["entry_km_m"] > c["exit_km_m"]  # running toward decreasing km
    assert c["entry_km_m"] == pytest.approx(ST - 0.8 * LT, abs=0.05)
    rows = proposed_rows(c, "S001")
    assert [r["seq"] for r in rows] == [1, 2, 3, 4, 5, 6]
    assert [r["attribute"] for r in rows] == ["straight", "transition", "right", "transition", "straight", "none"]
    kms = [r["km_m"] for r in rows]
    assert kms == sorted(kms, reverse=True)
    assert kms[0] == pytest.approx(ST + 20.0, abs=1.0) and kms[5] == pytest.approx(TS - 20.0, abs=1.0)
    assert [r["radius_m"] for r in rows] == [0.0, 0.0, round(c["radius_m"], 1), 0.0, 0.0, 0.0]


def test_too_few_passes_give_no_curve() -> None:
    assert survey_track(("0001", "D"), samples(n_pass=2), RULE).curves.empty


def test_a_radius_beyond_the_survey_limit_is_not_a_feature() -> None:
    s = samples()
    flat = TrackSamples(s.pass_id, s.km, s.kappa * R / 5000.0)  # R 5000 m
    assert survey_track(("0001", "D"), flat, RULE).curves.empty


def test_the_mean_profile_averages_passes_not_samples() -> None:
    s = TrackSamples(np.array([0, 0, 0, 1]), np.array([0.5, 0.6, 0.7, 0.8]), np.array([1.0, 1.0, 1.0, 3.0]))
    p = mean_profile(s, 2.0)
    assert p["kappa"].tolist() == [2.0] and p["passes"].tolist() == [2]


def _db(entry: float, exit_: float, attribute: str = "left", fid: str = "F001", radius: float = R) -> pd.DataFrame:
    kms = [TS - 20.0, TS, entry, exit_, ST, ST + 20.0]
    attrs = ["straight", "transition", attribute, "transition", "straight", "none"]
    return pd.DataFrame(
        {
            "line_code": "0001",
            "track": "D",
            "feature_id": fid,
            "seq": range(1, 7),
            "km_m": kms,
            "radius_m": [0.0, 0.0, radius, 0.0, 0.0, 0.0],
            "attribute": attrs,
            "role": "",
        }
    )


def _compare(db: pd.DataFrame, covered: bool = True) -> pd.DataFrame:
    tc = survey_track(("0001", "D"), samples(), RULE)
    cov = Coverage(np.arange(4), np.full(4, 0.0 if covered else 1e9), np.full(4, 1e6))
    return compare(db, {("0001", "D"): tc}, {("0001", "D"): cov}, CFG)


def test_a_right_feature_is_ok_and_a_shifted_one_moved() -> None:
    ok = _compare(_db(TS + 48.0, ST - 48.0))
    assert ok["status"].tolist() == ["ok"]
    moved = _compare(_db(TS + 48.0 + 30.0, ST - 48.0 + 30.0))
    assert moved["status"].tolist() == ["moved"]
    assert "km" in moved["reason"].iloc[0]
    assert moved["exit_diff_m"].iloc[0] == pytest.approx(-30.0, abs=0.1)


def test_a_wrong_direction_or_radius_is_moved_with_the_reason() -> None:
    row = _compare(_db(TS + 48.0, ST - 48.0, "right")).iloc[0]
    assert row["status"] == "moved" and row["reason"].startswith("direction")
    row = _compare(_db(TS + 48.0, ST - 48.0, radius=900.0)).iloc[0]
    assert row["status"] == "moved" and row["reason"].startswith("radius")


def test_a_curve_the_db_lacks_is_new_and_a_feature_the_runs_lack_not_seen() -> None:
    elsewhere = _db(TS + 48.0, ST - 48.0).assign(km_m=lambda f: f["km_m"] + 5000.0)
    out = _compare(elsewhere)
    assert sorted(out["status"]) == ["new", "not seen"]
    assert _compare(elsewhere, covered=False)["status"].tolist().count("unverified") == 1
