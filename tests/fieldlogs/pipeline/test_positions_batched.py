"""The positions frame's network columns made at once (:meth:`_Columns.fill_single`, the
``candidates`` cells of :func:`~fieldlogs.pipeline.claims.claims`): equal, cell for cell, to the
same columns made one fix (one cycle) at a time, on hand-made and random fixes."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fieldlogs.pipeline.positions as positions_mod
from dbtools.network import Network
from fieldlogs.pipeline.claims import Entry, _text, claims
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.pipeline.positions import margins, positions_frame
from fieldlogs.pipeline.types import Fix, Hypothesis
from schemas.enums import FixSource, PositionState
from tests.fieldlogs.pipeline.claims_reference import candidates_text

CFG = MarginConfig()


@pytest.fixture(scope="module")
def net(sample_network_db) -> Network:  # type: ignore[no-untyped-def]
    from dbtools.database import read_network

    return read_network(sample_network_db)


def one_at_a_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """positions_frame as before the batch: every single-candidate fix through ``fill``."""

    def each(self, travel, items, cfg):  # type: ignore[no-untyped-def]
        for f, sel in items:
            self.fill(travel, f, sel, cfg)

    monkeypatch.setattr(positions_mod._Columns, "fill_single", each)


def travel_of(net: Network, n: int, seed: int) -> Travel:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    v = rng.choice([0.0, 3.0, 15.0, 30.0], size=n)
    d = np.concatenate([[0.0], np.cumsum(v[1:] * 0.1)])
    motion = np.where(np.arange(n) < n // 2, 1, -1)
    s = np.cumsum(motion * np.diff(d, prepend=0.0))
    allowance = np.cumsum(rng.choice([0.0, 0.0, 0.4], size=n))
    return Travel(t, d, s, v, motion.astype(np.int8), np.ones(n, bool), allowance, net)


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_batched_frame_equals_fix_by_fix(net: Network, data: st.DataObject) -> None:
    """Random single- and multi-candidate fixes on the sample network's tracks (anywhere along
    them, near and beyond their ends, uncertain or not, with extra margins): the frame is the
    same as made one fix at a time."""
    lines = track_lines(net)
    ids = sorted(lines.lines)
    n = data.draw(st.integers(50, 600))
    tr = travel_of(net, n, data.draw(st.integers(0, 5)))
    times = sorted(data.draw(st.sets(st.integers(0, n - 1), min_size=1, max_size=30)))
    fixes = []
    for i in times:
        hyps = []
        for _ in range(data.draw(st.sampled_from([1, 1, 1, 2, 3]))):
            tid = data.draw(st.sampled_from(ids))
            length = lines[tid].length_m
            pos = data.draw(st.one_of(st.floats(-30.0, length + 30.0), st.sampled_from([0.0, length])))
            extra = data.draw(st.sampled_from([0.0, 0.0, 2.5]))
            hyps.append(Hypothesis(tid, pos, data.draw(st.sampled_from([1, -1])), extra))
        state = PositionState.DETERMINED if len(hyps) == 1 else PositionState.AMBIGUOUS
        since = data.draw(st.one_of(st.none(), st.floats(0.0, float(tr.d[i]))))
        if since is not None and len(hyps) == 1:
            state = PositionState.UNCERTAIN
        f = Fix(
            float(tr.t[i]), float(tr.s[i]), float(tr.d[i]), math.nan, math.nan, "", "", 1, FixSource.GPS,
            data.draw(st.floats(1.0, 20.0)), state, allowance_ref_m=float(tr.allowance[i]),
            uncertain_since_d=since, hyps=tuple(hyps),
        )  # fmt: skip
        fixes.append(f)
    if data.draw(st.booleans()):
        fixes.insert(len(fixes) // 2, Fix.undetermined(fixes[len(fixes) // 2].t_effective, 0.0, 0.0))
    batched = positions_frame(tr, fixes, CFG)
    with pytest.MonkeyPatch.context() as mp:
        one_at_a_time(mp)
        each = positions_frame(tr, fixes, CFG)
    pd.testing.assert_frame_equal(batched, each, check_exact=True)


def test_margins_of_fixes_laid_end_to_end() -> None:
    """Hand-computed: 1 m + 2 % of 100 m, + the slip budget over the reference (0.5 m), and
    while uncertain + 5 % of the travel since (10 m)."""
    a = Fix(0.0, 0.0, 0.0, 0.0, 0.0, "", "", 1, FixSource.GPS, 1.0, allowance_ref_m=0.5)
    b = Fix(0.0, 0.0, 50.0, 0.0, 0.0, "", "", 1, FixSource.GPS, 2.0, uncertain_since_d=90.0)
    d = np.array([100.0, 100.0, 100.0])
    allowance = np.array([1.0, 0.0, 1.0])
    m = margins([a, b], np.array([1, 2]), d, allowance, CFG)
    assert m.tolist() == pytest.approx([1.0 + 2.0 + 0.5, 2.0 + 1.0 + 0.0 + 0.5, 2.0 + 1.0 + 1.0 + 0.5])
    for f, sl in ((a, slice(0, 1)), (b, slice(1, 3))):
        assert m[sl].tolist() == positions_mod.margin_m(f, d[sl], allowance[sl], CFG).tolist()


value = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, -0.0004, 0.0005, 1e-7, 1e16, 123456.7895, math.nan, -math.inf]),
)


@settings(max_examples=150, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["A", "B", 'q"uote', "ü-track", "A"]),
            st.lists(st.tuples(value, value, value, st.booleans()), min_size=4, max_size=4),
        ),
        min_size=1,
        max_size=5,
    )
)
def test_candidates_cells_equal_the_encoder_cycle_by_cycle(spec: list[tuple[str, list[tuple]]]) -> None:  # type: ignore[type-arg]
    """Random entries (NaN, ±∞, −0, tiny and huge values, a track id to escape, a track
    repeated): every ambiguous cycle's cell is the JSON encoder's text of its items."""
    ents = []
    for j, (tid, rows) in enumerate(spec):
        pos, km, margin, mask = (np.array([r[k] for r in rows]) for k in range(4))
        ents.append(Entry(tid, pos, km, margin, mask.astype(bool) | (j == 0), 1, ("L", "D")))
    with np.errstate(invalid="ignore"):  # the km agreement of ±∞ (not what is tested here)
        cl = claims(ents)
    for i in range(4):
        want = candidates_text([e for e in ents if e.mask[i]], i) if cl.ambiguous[i] else None
        assert cl.text[i] == want


@settings(max_examples=2000, deadline=None)
@given(
    st.one_of(
        st.floats(),
        st.floats(-1e12, 1e12),
        st.integers(-(10**15), 10**15).map(lambda k: k / 1000.0),  # on the mm grid
        st.integers(-(10**6), 10**6).map(lambda k: k / 2048.0),  # exact binary ties at the 4th decimal
    )
)
def test_cell_number_text_is_repr_of_the_rounded_float(v: float) -> None:
    """The fast text of a number (``f"{v:.3f}"`` stripped) is ``repr(round(v, 3))`` — the JSON
    encoder's — on every float: huge, tiny, ties, −0, ±∞ and NaN (null)."""
    want = repr(round(v, 3)) if math.isfinite(v) else "null"
    assert _text(v) == want
    assert _text(-0.0004) == "-0.0" and _text(12.0) == "12.0" and _text(2.0625) == "2.062"
