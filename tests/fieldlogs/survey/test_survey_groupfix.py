"""G balises on a track off every line placed by dead reckoning from the run's earlier
position (fieldlogs/survey/groupfix.py, fieldlogs/survey/groups.py ``run_placements``).

Hand computation. Crossover X1 (no line; track points pos 0 ↔ km 21400, pos 60 ↔ km 21460),
group 800/8: G80 at km 21420 (pos 20), G81 at km 21423 (pos 23). A run at 5 m/s enters X1
at t = 2 s (pos 0 when the travel d = 10 m); the pipeline's position on X1 is the truth + e
(its earlier reference's error), margin 3 m; the reader is 1 m ahead of the reference point
(cab F). The reader reaches G80 when the reference point is at pos 19 (t = 5.8 s) and G81 at
pos 22 (t = 6.4 s). The group's first read corrects the pipeline (from t = 5.8 its position
jumps by −e): the reference is the cycle before t = 5.8, t = 5.7, pos 18.5 + e, d 28.5 m. So

    G80: p = 18.5 + e + λ·(29 − 28.5) + 1 = 20 + e (λ = 1)
    G81: p = 18.5 + e + (32 − 28.5) + 1 = 23 + e     (not 23 from the corrected position)

margins 3 + 2 %·0.5 = 3.01 m and 3 + 2 %·3.5 = 3.07 m. Three runs with e = +0.6, −0.3,
+0.3: mean +0.2, s = 0.4583, t₀.₉₇₅(2) = 4.303 → interval 4.303·0.4583/√3 + 3.01 = 4.149 m
(G80): residual km_db − km(20.2) = −0.2 m, inconclusive within it: unverified. A DB 8 m off
(G80 at km 21428) is moved (|−7.8| > 4.149).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dbtools.network import Network
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.groupfix import fix_status, group_fixes
from fieldlogs.survey.groups import TrackTrace, group_places, run_placements
from fieldlogs.survey.inspection import group_status

CFG = SurveyConfig()


def network(km_g80: float = 21420.0) -> Network:
    balises = pd.DataFrame(
        {
            "balise_id": ["G80", "G81"],
            "kind": ["G", "G"],
            "line_code": ["0420", "0420"],
            "station_code": [None, None],
            "track": [None, None],
            "signal_type": [None, None],
            "km_actual_m": [km_g80, 21423.0],
            "km_equipment_m": [km_g80, 21423.0],
            "track_id": ["X1", "X1"],
            "nid_c": [800, 800],
            "nid_bg": [8, 8],
            "n_pig": [0, 1],
        }
    )
    tracks = pd.DataFrame({"track_id": ["X1"], "line_code": [None], "track": [None], "length_m": [60.0]})
    tp = pd.DataFrame({"track_id": ["X1", "X1"], "pos_m": [0.0, 60.0], "km_m": [21400.0, 21460.0]})
    return Network({"balises": balises, "tracks": tracks, "track_points": tp}, origin="test")


def trace(e: float) -> TrackTrace:
    t = np.round(np.arange(0.0, 12.0, 0.1), 6)
    d = 5.0 * t
    on = t >= 2.0
    truth = d - 10.0
    u = np.where(on, truth + np.where(t < 5.8 - 1e-9, e, 0.0), np.nan)
    n = t.size
    return TrackTrace(
        t, d, u, np.full(n, 3.0), np.where(on, "X1", "").astype(object), np.ones(n, np.int64), np.asarray(on)
    )


READS = pd.DataFrame({"balise_id": ["G80", "G81"], "t": [5.8, 6.4]})


def test_placements_by_hand() -> None:
    places = group_places(network())
    assert places["place"].tolist() == pytest.approx([20.0, 23.0]) and places["off_line"].all()
    assert places["group"].tolist() == ["800/8", "800/8"]
    got = run_placements(places, trace(0.6), READS, reader_x_m=1.0, distance_pct=2.0)
    place = got["pos_ref_m"] + got["travel_m"] + got["reader_m"]
    assert place.tolist() == pytest.approx([20.6, 23.6])  # both from the reference before the group
    assert got["margin_m"].tolist() == pytest.approx([3.01, 3.07])


def test_a_read_without_a_reference_on_its_track_gives_no_place() -> None:
    tr = trace(0.0)
    late = pd.DataFrame({"balise_id": ["G80"], "t": [2.0]})  # the cycle before is not on X1
    assert run_placements(group_places(network()), tr, late, 0.0, 2.0).empty


@pytest.mark.parametrize(("km_g80", "status"), [(21420.0, "unverified"), (21428.0, "moved")])
def test_fixes_over_three_runs_by_hand(km_g80: float, status: str) -> None:
    net = network(km_g80)
    places = group_places(net)
    runs = [run_placements(places, trace(e), READS, 1.0, 2.0) for e in (0.6, -0.3, 0.3)]
    raw = group_fixes(runs, np.ones(3), net, places)
    fx = raw.set_index("balise_id")
    g80 = fx.loc["G80"]
    assert g80["n_estimates"] == 3 and g80["km_surveyed_m"] == pytest.approx(21420.2)
    assert g80["residual_m"] == pytest.approx(km_g80 - 21420.2)
    assert g80["ci95_m"] == pytest.approx(4.3027 * np.std([0.6, -0.3, 0.3], ddof=1) / np.sqrt(3) + 3.01, abs=1e-3)
    assert fix_status(g80, CFG)[0] == status
    # the wheel scale stretches the dead-reckoned travel: λ = 1.01 adds 1 % of 0.5 m
    fx2 = group_fixes(runs, np.full(3, 1.01), net, places).set_index("balise_id")
    assert fx2.loc["G80", "km_surveyed_m"] == pytest.approx(21420.205)
    reads = pd.Series({"G80": 3, "G81": 3})
    rows = group_status(net, {"G80": "X1", "G81": "X1"}, pd.DataFrame(), reads, CFG, fixes=raw)
    row = rows.set_index("balise_id").loc["G80"]
    assert row["status"] == status and row["n_estimates"] == 3 and "dead reckoning" in row["reason"]


def test_few_passes_and_a_tight_interval() -> None:
    one = pd.Series({"n_estimates": 1, "residual_m": 0.1, "ci95_m": np.nan, "margin_m": 3.0})
    assert fix_status(one, CFG)[0] == "unverified"
    tight = pd.Series({"n_estimates": 5, "residual_m": 0.1, "ci95_m": 0.5, "margin_m": 0.4})
    assert fix_status(tight, CFG) == ("ok", fix_status(tight, CFG)[1])


def test_the_sample_crossover_run_places_group_bg8(sample_network_db, tmp_path) -> None:  # type: ignore[no-untyped-def]
    # the bundled crossover run reads BG8 on crossover 0420-X1: placed from the run's position
    # before the group (simulated on the DB's places: within the margin of about 4 m)
    import shutil
    from pathlib import Path

    from fieldlogs.survey.runner import survey

    logs = Path(__file__).parents[3] / "fieldlogs" / "sample_logs" / "sim-net-crossover"
    shutil.copytree(logs, tmp_path / "sim-net-crossover")
    b = survey([tmp_path], sample_network_db, workers=1).balises.set_index("balise_id")
    for bid in ("BG8.0", "BG8.1"):
        row = b.loc[bid]
        assert row["track_id"] == "0420-X1" and row["n_estimates"] == 1 and row["status"] == "unverified"
        assert abs(row["residual_m"]) < 1.0 and "dead reckoning" in row["reason"]
