"""The positions frame's text columns (issue 21): every cycle's cell refers to one str object
per distinct value, not to a str of its own (≈ 60 B a cycle per column on a long run)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pandas as pd
import pytest

import fieldlogs.pipeline.positions as positions_mod
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.positions import positions_frame, text_column
from fieldlogs.pipeline.types import Fix
from schemas.enums import FixSource, PositionState


def _travel(seconds: float = 600.0) -> Travel:
    t = np.arange(0.0, seconds + 1e-9, 0.1)
    d = 10.0 * t
    n = t.size
    return Travel(t, d, d.copy(), np.full(n, 10.0), np.ones(n, np.int8), np.ones(n, bool), np.zeros(n))


def _fixes() -> list[Fix]:
    """Fixes of every source and state, one after another (from 10 s on; none before)."""

    def fix(t: float, source: FixSource, state: PositionState = PositionState.DETERMINED) -> Fix:
        return Fix(t, 10.0 * t, 10.0 * t, 1000.0 + 10.0 * t, 1000.0 + 10.0 * t, "L1", "D", 1, source, 1.0, state)

    return [
        fix(10.0, FixSource.BALISE),
        fix(100.0, FixSource.FEATURE),
        fix(200.0, FixSource.GPS, PositionState.UNCERTAIN),
        Fix.undetermined(300.0, 3000.0, 3000.0),
        fix(400.0, FixSource.GNSS),
        fix(500.0, FixSource.BALISE, PositionState.UNCERTAIN),
    ]


def test_text_column_cells_refer_to_the_values_objects() -> None:
    values = {"undetermined": 0, "determined": 1, "uncertain": 2}
    codes = np.array([0, 1, 1, 2, 0, 2, 2], dtype=np.uint8)
    col = text_column(codes, values)
    assert col.dtype == object and col.tolist() == [list(values)[c] for c in codes]
    assert {id(v) for v in col} == {id(v) for v in values}


def test_positions_text_columns_share_one_str_per_value(monkeypatch: pytest.MonkeyPatch) -> None:
    """The object arrays handed to pandas hold as many distinct objects as values (with
    ``np.full(n, text, dtype=object)`` the state column held a new str in every cell)."""
    handed: list[np.ndarray] = []

    def frame(columns: dict[str, Any]) -> pd.DataFrame:
        handed.extend(v for v in columns.values() if isinstance(v, np.ndarray) and v.dtype == object)
        return pd.DataFrame(columns)

    def array(values: Any, dtype: str) -> Any:
        handed.append(values)
        return pd.array(values, dtype=dtype)

    monkeypatch.setattr(positions_mod, "pd", SimpleNamespace(DataFrame=frame, array=array))
    travel = _travel()
    pos = positions_frame(travel, _fixes(), MarginConfig())
    assert len(handed) == 6  # state, line_code, track, track_id, last_fix_source, candidates
    for col in handed:
        assert col.size == travel.n
        assert len({id(v) for v in col}) == len(set(col.tolist()))
    assert set(pos["state"]) == {str(s) for s in PositionState} - {"ambiguous"}  # line fixes: never ambiguous
    assert set(pos["last_fix_source"]) == {str(s) for s in FixSource}


def test_positions_frame_values_and_dtypes() -> None:
    """Each cycle's texts are those of the fix in force ("undetermined"/"none" before the
    first and under an undetermined one), in the frame's dtypes of before."""
    frame = positions_frame(_travel(), _fixes(), MarginConfig())
    pos = frame.set_index(frame["t"].round(1))
    expect = {
        5.0: ("undetermined", "none", None),
        50.0: ("determined", "balise", "L1"),
        150.0: ("determined", "feature", "L1"),
        250.0: ("uncertain", "gps", "L1"),
        350.0: ("undetermined", "none", None),
        450.0: ("determined", "gnss", "L1"),
        550.0: ("uncertain", "balise", "L1"),
    }
    for t, (state, source, line) in expect.items():
        row = pos.loc[t]
        assert (row["state"], row["last_fix_source"]) == (state, source)
        assert (row["line_code"] is pd.NA) if line is None else row["line_code"] == line
    assert pos["state"].dtype == pd.StringDtype(na_value=np.nan)
    for c in ("line_code", "track", "last_fix_source"):
        assert pos[c].dtype == pd.StringDtype()
