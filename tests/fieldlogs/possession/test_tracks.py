"""The wrong-track rule among n tracks (``fieldlogs.possession.tracks``): hand-made stretches on
a hand-made topology, and a hand-made plan on the sample network's crossover run."""

from __future__ import annotations

import json
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.topology import Topology
from fieldlogs.possession.check import check_run
from fieldlogs.possession.plan import Possession, load_plan, plan_frame, read_plan
from fieldlogs.possession.tracks import crossover_between, possessed_at, track_alarms
from fieldlogs.runs.handle import read_run
from schemas.enums import AlarmType, NoticeType

DATA = Path(__file__).parents[2] / "data" / "possession_network"
RUN = Path(__file__).parents[3] / "fieldlogs" / "sample_logs" / "sim-net-crossover"
T0 = datetime(2026, 1, 15, 2, 0, tzinfo=UTC)

#: A (main) —end/begin— X (crossover) —end/begin— B (main); C a station track beside B; X also
#: touches D at its begin through a `none` relation (the other branch of the switch).
TOPO = Topology(
    tracks=pd.DataFrame(
        {"track_id": ["A", "B", "C", "D", "X"], "kind": ["main", "main", "station", "main", "crossover"]}
    ),
    connections=pd.DataFrame(
        [
            ("X", "begin", "A", "end", "both"),
            ("X", "begin", "D", "begin", "none"),
            ("X", "end", "B", "begin", "both"),
            ("C", "begin", "A", "end", "both"),
            ("C", "end", "B", "begin", "both"),
        ],
        columns=["track_a", "end_a", "track_b", "end_b", "navigability"],
    ).assign(switch_id=None),
)


def _poss(work: str, track_id: str | None, *, started: float | None = 0.0, released: float | None = None) -> Possession:
    def at(s: float | None) -> datetime | None:
        return None if s is None else T0 + timedelta(seconds=s)

    return Possession(
        work,
        "0900",
        "D",
        0.0,
        9000.0,
        T0 - timedelta(hours=1),
        T0 + timedelta(hours=2),
        at(started),
        at(released),
        track_id=track_id,
    )


def _positions(stretches: list[tuple[str, ...]]) -> pd.DataFrame:
    """Two 0.1 s cycles per stretch: ("determined", track) or ("ambiguous", candidate, …)."""
    rows = []
    for state, *tracks in stretches:
        for _ in range(2):
            cands = json.dumps([{"track_id": c, "pos_m": 1.0, "km_m": None, "margin_m": 1.0} for c in tracks])
            rows.append((state, tracks[0] if state == "determined" else None, None if state == "determined" else cands))
    return pd.DataFrame(
        {
            "t": np.arange(len(rows)) * 0.1,
            "state": [r[0] for r in rows],
            "line_code": None,
            "track": None,
            "track_id": [r[1] for r in rows],
            "pos_m": 1.0,
            "speed_mps": 5.0,
            "candidates": [r[2] for r in rows],
        }
    )


def test_rule_among_n_tracks_on_hand_made_stretches() -> None:
    pos = _positions(
        [
            ("determined", "A"),  # possessed: nothing
            ("ambiguous", "A", "X"),  # every candidate allowed (X: a crossover between A and B): nothing
            ("determined", "X"),  # the crossover ride: a notice, no alarm
            ("ambiguous", "X", "B", "C"),  # C not allowed: unconfirmed (notice)
            ("determined", "B"),
            ("determined", "C"),  # a station track not possessed: alarm
            ("ambiguous", "C", "D"),  # no candidate allowed: alarm
        ]
    )
    alarms, notices = track_alarms(pos, [_poss("W1", "A"), _poss("W2", "B"), _poss("W0", None)], T0, TOPO)
    assert [(a.type, a.track, a.t) for a in alarms] == [
        (AlarmType.WRONG_TRACK, "C", pytest.approx(1.0)),
        (AlarmType.WRONG_TRACK, None, pytest.approx(1.2)),
    ]
    assert alarms[1].evidence["candidates"] == ["C", "D"] and alarms[0].evidence["possessed"] == ["A", "B"]
    assert [(n.type, n.track, n.t) for n in notices] == [
        (NoticeType.CROSSOVER, "X", pytest.approx(0.4)),
        (NoticeType.TRACK_UNCONFIRMED, None, pytest.approx(0.6)),
    ]
    assert notices[0].evidence["between"] == ["A", "B"] and notices[0].work_no == "W1"


def test_a_crossover_to_an_unpossessed_track_is_a_wrong_track() -> None:
    """Only A possessed: X leads to B, which is not possessed — no crossover ride between
    possessed tracks, so claimed on X is the alarm (and the `none` branch D never counts)."""
    assert crossover_between(TOPO, "X", {"A": "W1", "D": "W9"}) is None
    assert crossover_between(TOPO, "C", {"A": "W1", "B": "W2"}) is None  # a station loop is no crossover
    alarms, notices = track_alarms(_positions([("determined", "A"), ("determined", "X")]), [_poss("W1", "A")], T0, TOPO)
    assert [(a.type, a.track) for a in alarms] == [(AlarmType.WRONG_TRACK, "X")] and notices == []


def test_only_started_possessions_allow_a_track() -> None:
    p = [_poss("W1", "A", started=None), _poss("W2", "B", started=0.0, released=0.3), _poss("W3", "C")]
    assert possessed_at(p, T0 + timedelta(seconds=0.1)) == {"B": "W2", "C": "W3"}
    assert possessed_at(p, T0 + timedelta(seconds=0.3)) == {"C": "W3"}
    # none with a track_id: the rule does not apply (the km rules judge the line and track)
    assert track_alarms(_positions([("determined", "A")]), [_poss("W0", None)], T0, TOPO) == ([], [])


def test_plan_on_the_sample_network_crossover_run(sample_network_db: Path) -> None:
    net = read_network(sample_network_db)
    plan = load_plan(DATA / "crossover_plan.csv", net)
    assert {p.work_no: p.track_id for p in plan.possessions} == {
        "N-01": "0420-U5",
        "N-02": "0420-U4",
        "N-03": "0420-D3",
        "N-04": "0420-D2",
    }
    res = check_run(read_run(RUN), net, plan.possessions)
    wrong = [a for a in res.alarms if a.type == AlarmType.WRONG_TRACK]
    # U5 → U4 → X1 → D3 → D2 possessed or a crossover between them; on to D1: the alarm
    assert [(a.track, a.evidence["track_id"]) for a in wrong] == [("0420-D1", "0420-D1")]
    xo = [n for n in res.notices if n.type == NoticeType.CROSSOVER and n.track == "0420-X1"]
    assert len(xo) == 1 and xo[0].evidence["between"] == ["0420-D3", "0420-U4"]
    unconfirmed = [n for n in res.notices if n.type == NoticeType.TRACK_UNCONFIRMED]
    assert unconfirmed and all(set(n.evidence["candidates"]) & set(n.evidence["possessed"]) for n in unconfirmed)
    assert all(a.t < xo[0].t or a.t > 200.0 for a in res.alarms)  # no alarm on the crossover ride


def test_unknown_track_id_is_a_plan_error(sample_network_db: Path, tmp_path: Path) -> None:
    text = (DATA / "crossover_plan.csv").read_text().replace("0420-D2\n", "0420-D9\n")
    bad = tmp_path / "plan.csv"
    bad.write_text(text)
    plan = read_plan(bad, read_network(sample_network_db))
    errors = [(f.rule, f.row, f.column) for f in plan.errors]
    assert errors == [("plan.unknown_track_id", 5, "track_id")]
    assert "0420-D9" in plan.errors[0].message and "0420-D2" in plan.errors[0].message


def test_plan_frame_writes_track_id_only_when_a_possession_has_one(sample_network_db: Path, tmp_path: Path) -> None:
    plan = load_plan(DATA / "crossover_plan.csv", read_network(sample_network_db))
    frame = plan_frame(plan.possessions)
    assert list(frame["track_id"]) == ["0420-U5", "0420-U4", "0420-D3", "0420-D2"]
    frame.to_csv(tmp_path / "again.csv", index=False)
    again = load_plan(tmp_path / "again.csv", read_network(sample_network_db))
    assert [p.track_id for p in again.possessions] == [p.track_id for p in plan.possessions]
    assert "track_id" not in plan_frame([_poss("W0", None)]).columns  # line-only plans keep their columns
