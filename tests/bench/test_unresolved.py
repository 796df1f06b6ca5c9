"""``bench/_causes.py``'s reasons for a facing passage never resolved (issue 31): hand-computed."""

from __future__ import annotations

import pandas as pd
import pytest

from tests.bench.scripts import load_script

causes = load_script("_causes")


def _passages(rows: list[tuple[float, str, bool]]) -> pd.DataFrame:
    return pd.DataFrame(rows, columns=["t", "switch_id", "resolved"])


# truth: 10 m/s from t 0 to 100 s (1000 m), so a passage at t leaves 1000 − 10·t m of run
TRUTH = pd.DataFrame({"t": [0.0, 50.0, 100.0], "speed_mps": [10.0, -10.0, 10.0]})
LEAD = {"W1": 24.9, "W2": 22.0}


def test_run_ending_within_the_lead() -> None:
    # W1 passed at t 98.7: 13 m left < R·α 24.9 m; W2 at 97.9: 21 m left < 22 m; resolved ones not listed
    p = _passages([(98.7, "W1", False), (97.9, "W2", False), (10.0, "W1", True)])
    got = causes.unresolved(p, TRUTH, None, False, LEAD)
    assert [r for r, _ in got] == ["run ended within the lead"] * 2
    assert [d for _, d in got] == pytest.approx([13.0, 21.0])


def test_balise_only_without_a_group_after_the_switch() -> None:
    # passage at t 50 (500 m left): a G read at t 40 (before) and a C read at t 60 do not count
    tel = pd.DataFrame({"t": [40.0, 60.0], "kind": ["G", "C"]})
    p = _passages([(50.0, "W1", False)])
    assert causes.unresolved(p, TRUTH, tel, True, LEAD) == [("balise-only, no group after the switch", 500.0)]
    # a G read after it: evidence was there, so the passage is "other"
    tel2 = pd.DataFrame({"t": [40.0, 70.0], "kind": ["G", "G"]})
    assert causes.unresolved(p, TRUTH, tel2, True, LEAD) == [("other", 500.0)]
    # with another sensor the condition is not balise-only: "other" too
    assert causes.unresolved(p, TRUTH, tel, False, LEAD) == [("other", 500.0)]
