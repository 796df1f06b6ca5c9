"""The GIS-verify page's verdict: green only when no line is mostly unverified."""

from __future__ import annotations

import pandas as pd

from dbtools.pagekit import Status, Verdict
from fieldlogs.gisverify.page import mostly_unverified, verdict


def coverage(unverified_d: float, unverified_u: float) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "line_code": ["0420", "0420", "0500"],
            "track": ["D", "U", "S"],
            "length_km": [4.0, 4.0, 2.0],
            "unverified_km": [unverified_d, unverified_u, 0.2],
        }
    )


def test_green_only_when_most_of_every_line_is_verified() -> None:
    assert verdict(coverage(1.0, 2.9), 0) == Verdict("Passed: no defect found.", Status.OK)  # 3.9 of 8 km: not most
    v = verdict(coverage(1.5, 3.0), 0)  # 4.5 of 8 km unverified
    text = v.text
    assert v.status == Status.CAUTION and text.startswith("Mostly unverified: ")
    assert "line 0420: 4.5 of 8.0 km unverified" in text and "0500" not in text
    assert mostly_unverified(coverage(1.5, 3.0))["where"].tolist() == ["line 0420"]


def test_defects_are_red_and_empty_coverage_is_not_green() -> None:
    assert verdict(coverage(4.0, 4.0), 2) == Verdict("Failed: 2 defect(s) found.", Status.WARN)
    assert verdict(coverage(0.0, 0.0).iloc[:0], 0).status == Status.CAUTION
