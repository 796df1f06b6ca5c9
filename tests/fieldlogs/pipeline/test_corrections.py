"""One position-correction statistic for run, audit and report (issue 14)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fieldlogs.pipeline.corrections import STAT_COLUMNS, correction_stats, run_correction_stats
from schemas.enums import EventType

B, F = str(EventType.BALISE_CORRECTION), str(EventType.FEATURE_CORRECTION)


def _events(rows: list[tuple[str, float | None]], run: str = "a") -> pd.DataFrame:
    return pd.DataFrame(
        {
            "run": run,
            "type": [r[0] for r in rows],
            "correction_pct": [np.nan if r[1] is None else r[1] for r in rows],
        }
    )


def test_balise_population_by_hand() -> None:
    ev = _events([(B, None), (B, 0.2), (F, 3.0), (B, 0.6), ("slip", None), (B, 0.7)])
    s = run_correction_stats(ev, target_pct=0.5)
    # the first balise correction has no % (no previous correction): counted, not averaged
    assert s["n_corrections"] == 4
    assert s["mean_correction_pct"] == pytest.approx(0.5)
    assert s["median_correction_pct"] == pytest.approx(0.6)
    assert s["max_correction_pct"] == pytest.approx(0.7)
    assert s["share_above_target"] == pytest.approx(2 / 3)
    a = run_correction_stats(ev, population="all", target_pct=0.5)
    assert a["n_corrections"] == 5 and a["max_correction_pct"] == pytest.approx(3.0)
    assert a["mean_correction_pct"] == pytest.approx((0.2 + 3.0 + 0.6 + 0.7) / 4)


def test_no_corrections_is_undefined_not_zero() -> None:
    s = run_correction_stats(_events([("slip", None)]))
    assert s["n_corrections"] == 0
    assert all(s[c] is None for c in STAT_COLUMNS if c != "n_corrections")


def test_groups_reindexed_keep_empty_groups() -> None:
    ev = pd.concat([_events([(B, 0.4), (B, 0.2)], "a"), _events([(F, 1.0)], "b")])
    out = correction_stats(ev, ["run"], index=pd.Index(["a", "b", "c"], name="run"))
    assert out.loc["a", "n_corrections"] == 2 and out.loc["a", "mean_correction_pct"] == pytest.approx(0.3)
    assert out.loc["b", "n_corrections"] == 0 and math.isnan(out.loc["b", "mean_correction_pct"])
    assert out.loc["c", "n_corrections"] == 0


@given(
    st.lists(
        st.tuples(st.sampled_from([B, F, "slip"]), st.one_of(st.none(), st.floats(0.0, 10.0))),
        max_size=30,
    ),
    st.floats(0.0, 5.0),
)
def test_grouped_equals_per_run(rows: list[tuple[str, float | None]], target: float) -> None:
    """The grouped statistic of a run is its per-run statistic (report ≡ run ≡ audit)."""
    half = len(rows) // 2
    ev = pd.concat([_events(rows[:half], "a"), _events(rows[half:], "b")], ignore_index=True)
    grouped = correction_stats(ev, ["run"], target_pct=target, index=pd.Index(["a", "b"], name="run"))
    for run in ("a", "b"):
        single = run_correction_stats(ev[ev["run"] == run], target_pct=target)
        for c in STAT_COLUMNS:
            g = grouped.loc[run, c]
            if single[c] is None:
                assert math.isnan(g)
            else:
                assert g == pytest.approx(single[c])
