"""The telegram rows the balise aids hear (:func:`~fieldlogs.pipeline.aids.balise.telegram_rows`,
issue 31: the engine's cost, results unchanged): the same dicts, key for key and value for value
— type and repr included — as ``astype(object).where(notna, None).to_dict("records")``, on the
telegram stream's dtypes and the others a frame may hold."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.database import read_network
from fieldlogs.pipeline.aids.balise import BaliseAid, telegram_observations, telegram_rows
from fieldlogs.pipeline.aids.balise_group import BaliseGroupAid
from fieldlogs.pipeline.aids.registry import position_aids
from fieldlogs.pipeline.aids.track_balise import TrackBaliseAid
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.run import prepare_run
from fieldlogs.runs.handle import read_run
from tests.fieldlogs.pipeline.conftest import SAMPLE_LOGS


def reference(tel: pd.DataFrame) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = tel.astype(object).where(tel.notna(), None).to_dict("records")  # type: ignore[assignment]
    return out


def same(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> bool:
    return len(a) == len(b) and all(
        list(x) == list(y) and all(type(x[k]) is type(y[k]) and repr(x[k]) == repr(y[k]) for k in x)
        for x, y in zip(a, b, strict=True)
    )


def test_hand_made_telegrams() -> None:
    # the I2 telegrams of a network run: float t, strings and nullable ints with NA cells
    tel = pd.DataFrame(
        {
            "t": [126.638, 279.596, np.nan],
            "kind": pd.array(["I2", "I2", None], dtype="string"),
            "track": pd.array(["D", None, "U"], dtype="string"),
            "nid_c": pd.array([None, 7, 8], dtype="Int64"),
        }
    )
    rows = telegram_rows(tel)
    assert rows == [
        {"t": 126.638, "kind": "I2", "track": "D", "nid_c": None},
        {"t": 279.596, "kind": "I2", "track": None, "nid_c": 7},
        {"t": None, "kind": None, "track": "U", "nid_c": 8},
    ]
    assert type(rows[1]["nid_c"]) is int and type(rows[0]["t"]) is float
    assert same(rows, reference(tel))
    assert [o.t for o in telegram_observations(rows, lambda r: r["t"] is not None)] == [126.638, 279.596]


def test_without_pandas_boxing_the_slow_path(monkeypatch: pytest.MonkeyPatch) -> None:
    # a pandas release without ``maybe_box_native`` where it is imported from: the old expression
    import fieldlogs.pipeline.aids.balise as balise

    tel = pd.DataFrame({"t": [1.5, np.nan], "nid_c": pd.array([None, 7], dtype="Int64")})
    monkeypatch.setattr(balise, "maybe_box_native", None)
    rows = telegram_rows(tel)
    assert rows == [{"t": 1.5, "nid_c": None}, {"t": None, "nid_c": 7}]
    assert same(rows, reference(tel))


def test_empty_and_odd_frames() -> None:
    empty = pd.DataFrame({"t": pd.Series([], dtype=float), "kind": pd.array([], dtype="string")})
    assert telegram_rows(empty) == [] == reference(empty)
    no_columns = pd.DataFrame(index=range(2))
    assert same(telegram_rows(no_columns), reference(no_columns))
    twice = pd.DataFrame([[1, 2]], columns=["a", "a"])  # to_dict's own handling (the last wins)
    with pytest.warns(UserWarning, match="not unique"):
        assert same(telegram_rows(twice), [{"a": 2}])


COLUMNS: dict[str, Callable[[list[float], list[bool]], pd.Series[Any]]] = {
    "float": lambda xs, na: pd.Series([np.nan if m else x for x, m in zip(xs, na, strict=True)], dtype=float),
    "Float64": lambda xs, na: pd.Series(pd.array([None if m else x for x, m in zip(xs, na, strict=True)], "Float64")),
    "Int64": lambda xs, na: pd.Series(pd.array([None if m else int(x) for x, m in zip(xs, na, strict=True)], "Int64")),
    "int": lambda xs, na: pd.Series([int(x) for x in xs], dtype="int64"),
    "string": lambda xs, na: pd.Series(
        pd.array([None if m else f"{x:g}" for x, m in zip(xs, na, strict=True)], "string")
    ),
    "boolean": lambda xs, na: pd.Series(
        pd.array([None if m else x > 0 for x, m in zip(xs, na, strict=True)], "boolean")
    ),
    "bool": lambda xs, na: pd.Series([x > 0 for x in xs], dtype=bool),
    "object": lambda xs, na: pd.Series([None if m else f"{x:.1f}" for x, m in zip(xs, na, strict=True)], dtype=object),
    # numpy scalars in an object column: to_dict boxes them (int, float, bool)
    "numpy": lambda xs, na: pd.Series(
        [
            None if m else (np.int64(int(x)), np.float64(x / 4), np.bool_(x > 0))[int(x) % 3]
            for x, m in zip(xs, na, strict=True)
        ],
        dtype=object,
    ),
    "datetime": lambda xs, na: pd.Series(
        pd.to_datetime(pd.Series([np.nan if m else x for x, m in zip(xs, na, strict=True)], dtype=float), unit="s")
    ),
}


@settings(max_examples=150, deadline=None)
@given(
    st.integers(0, 6).flatmap(
        lambda n: st.tuples(
            st.lists(st.sampled_from(sorted(COLUMNS)), min_size=1, max_size=8),
            st.lists(st.lists(st.integers(-1000, 1000), min_size=n, max_size=n), min_size=8, max_size=8),
            st.lists(st.lists(st.booleans(), min_size=n, max_size=n), min_size=8, max_size=8),
        )
    )
)
def test_rows_equal_to_dict_records(case: tuple[list[str], list[list[int]], list[list[bool]]]) -> None:
    kinds, values, missing = case
    tel = pd.DataFrame(
        {
            f"c{j}_{kind}": COLUMNS[kind]([v / 8 if kind in ("float", "Float64") else v for v in values[j]], missing[j])
            for j, kind in enumerate(kinds)
        }
    )
    assert same(telegram_rows(tel), reference(tel))


def test_a_run_converts_its_telegrams_once_for_every_balise_aid(sample_network_db: Path) -> None:
    """On a network run with I1/I2/C and G telegrams the three balise aids share the run's one
    conversion (:attr:`RunContext.telegrams`), each hearing its own kinds, in the stream's order."""
    run = read_run(SAMPLE_LOGS / "sim-net-crossover")
    ctx, _ = prepare_run(run, read_network(sample_network_db), PipelineConfig())
    tel = ctx.streams["balise"]
    assert tel is not None and {"I2", "G"} <= set(tel["kind"].dropna())
    aids = {a.name: a for a in position_aids(ctx)}
    line, group, track = aids["balise"], aids["balise_group"], aids["track_balise"]
    assert isinstance(line, BaliseAid) and isinstance(group, BaliseGroupAid) and isinstance(track, TrackBaliseAid)
    assert line.telegrams is group.telegrams is track.telegrams is ctx.telegrams
    assert same(ctx.telegrams, reference(tel))
    kinds = tel["kind"].tolist()
    kinds_heard: list[tuple[BaliseAid | BaliseGroupAid | TrackBaliseAid, set[str]]] = [
        (line, {"I1", "I2", "C"}),
        (group, {"G"}),
        (track, {"I2"}),
    ]
    assert set(kinds) <= {"I1", "I2", "C", "G"}
    for aid, hears in kinds_heard:
        heard = [o.payload for o in aid.observations()]
        assert heard == [row for row, k in zip(ctx.telegrams, kinds, strict=True) if k in hears]
