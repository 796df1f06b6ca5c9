"""Per-run extraction: segments with their backward extension, telegram identification."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dbtools.network import Network
from fieldlogs.survey.dbindex import balise_index
from fieldlogs.survey.extract import find_segments, usable_intervals

BALISES = pd.DataFrame(
    {
        "balise_id": ["P1-D-I1", "P1-D-I2", "D-C1", "D-C2", "P2-U-I1", "P2-U-I2", "U-C1"],
        "kind": ["I1", "I2", "C", "C", "I1", "I2", "C"],
        "line_code": "0420",
        "station_code": ["01", "01", "01", "01", "02", "02", "02"],
        "track": ["D", "D", "D", "D", "U", "U", "U"],
        "signal_type": [None, None, "home", "block", None, None, "home"],
        "km_actual_m": [1000.0, 1005.0, 2000.0, 2600.0, 3000.0, 2995.0, 2000.0],
        "km_equipment_m": [1000.0, 1005.0, 2000.0, 2600.0, 3000.0, 2995.0, 2000.0],
        "dist_from_initial_m": [None, None, 1000.0, 1600.0, None, None, 995.0],
    }
)
INDEX = balise_index(Network({"balises": BALISES}))


def tel(kind: str, km: float, line: str = "", station: str = "", track: str = "", sig: str = "") -> dict[str, object]:
    return {
        "kind": kind,
        "tel_line_code": line,
        "tel_station_code": station,
        "tel_track": track,
        "tel_signal_type": sig,
        "km_est_m": km,
    }


def test_telegrams_are_identified_by_content_and_nearest_km() -> None:
    assert INDEX.identify(tel("I1", 1003.0, line="0420"), "0420", "D", 1, 50.0)[:2] == ("P1-D-I1", "0420")
    assert INDEX.identify(tel("I2", 1010.0, station="01", track="D"), "0420", "D", 1, 50.0)[0] == "P1-D-I2"
    assert INDEX.identify(tel("C", 2590.0, sig="block"), "0420", "D", 1, 50.0)[0] == "D-C2"
    hit = INDEX.identify(tel("C", 2030.0, sig="home"), "0420", "D", 1, 50.0)
    assert hit is not None and hit[0] == "D-C1" and hit[3] == pytest.approx(30.0)


def test_an_unknown_or_distant_telegram_is_not_identified() -> None:
    assert INDEX.identify(tel("C", 2300.0, sig="home"), "0420", "D", 1, 50.0) is None  # no home C there
    assert INDEX.identify(tel("C", 2000.0, sig="distant"), "0420", "D", 1, 50.0) is None
    assert INDEX.identify(tel("I2", 1005.0, station="09", track="D"), "0420", "D", 1, 50.0) is None


def test_a_balise_read_against_its_tracks_direction_is_not_identified_but_recognised() -> None:
    t = {**tel("C", 2000.0, sig="home"), "track": "U"}
    assert INDEX.identify(t, "0420", "U", 1, 50.0) is None  # U balise while km increases
    assert INDEX.against(t, "0420", 1)
    assert INDEX.identify(t, "0420", "U", -1, 50.0)[0] == "U-C1"


def test_passes_look_up_only_the_balises_of_a_track_running_that_way() -> None:
    assert INDEX.on_track("0420", "D", -1) is None
    group = INDEX.on_track("0420", "D", 1)
    assert group is not None and sorted(group.ids) == ["D-C1", "D-C2", "P1-D-I1", "P1-D-I2"]


def _positions(state: list[str], km: list[float], line: str = "0420", track: str = "D") -> pd.DataFrame:
    n = len(state)
    return pd.DataFrame(
        {
            "t": np.arange(n, dtype=float),
            "state": state,
            "line_code": pd.array([line if s != "undetermined" else None for s in state], dtype="string"),
            "track": pd.array([track if s != "undetermined" else None for s in state], dtype="string"),
            "km_m": [k if s != "undetermined" else np.nan for s, k in zip(state, km, strict=True)],
        }
    )


def test_the_first_segment_is_extended_back_over_the_undetermined_start() -> None:
    d = np.arange(10, dtype=float) * 20.0
    pos = _positions(["undetermined"] * 4 + ["determined"] * 6, list(1080.0 + d))
    segs = find_segments(pos, d, np.ones(10, dtype=int), extrapolate_m=50.0)
    assert len(segs) == 1
    g = segs[0]
    assert (g.ia, g.ib, g.motion) == (4, 10, 1)
    assert g.ie == 2  # back by at most 50 m of travel: cycles 2, 3 (d 40, 60) of 0–60
    segs = find_segments(pos, d, np.ones(10, dtype=int), extrapolate_m=1e6)
    assert segs[0].ie == 0


def test_a_cab_reversal_or_a_track_change_starts_a_new_segment() -> None:
    d = np.arange(8, dtype=float) * 40.0
    km = [1000.0, 1040.0, 1080.0, 1120.0, 1080.0, 1040.0, 1000.0, 960.0]
    cab = np.array([1, 1, 1, 1, -1, -1, -1, -1])
    segs = find_segments(_positions(["determined"] * 8, km), d, cab, 1000.0)
    assert [(g.ia, g.ib, g.motion, g.cab) for g in segs] == [(0, 4, 1, 1), (4, 8, -1, -1)]
    assert segs[1].ie == 4  # no extension over known cycles


def test_a_segment_moving_less_than_50_m_has_no_direction() -> None:
    pos = _positions(["determined"] * 3, [1000.0, 1010.0, 1020.0])
    segs = find_segments(pos, np.array([0.0, 10, 20]), np.ones(3), 0.0)
    assert segs[0].motion == 0


def test_usable_curvature_intervals_bridge_short_gaps_only() -> None:
    x = np.arange(0.0, 100.0, 2.5)
    ok = np.ones(x.size, dtype=bool)
    ok[10:14] = False  # 10 m gap: bridged
    ok[20:30] = False  # 25 m gap: a break
    cov = usable_intervals(x, ok, np.zeros(x.size, dtype=np.int64))
    assert cov[["x0_m", "x1_m"]].to_numpy().tolist() == [[0.0, 47.5], [75.0, 97.5]]
