"""The topology aid's lower bound on its next rule (:meth:`TopologyAid.not_before`): never after
the cycle its full forward scan finds, on hand-worked and random candidates of the hand-made
networks (joints with and without exits, reversals, standstills, extra margins)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.aid import drained
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.pipeline.types import Fix, Hypothesis
from schemas.enums import FixSource, PositionState
from tests.fieldlogs.pipeline.network_cases import MARGIN, net, travel


def fix_of(hyps: list[Hypothesis], s_ref: float = 0.0, d_ref: float = 0.0, unc: float = 5.0) -> Fix:
    state = PositionState.DETERMINED if len(hyps) == 1 else PositionState.AMBIGUOUS
    nan = math.nan
    return Fix(0.0, s_ref, d_ref, nan, nan, "", "", 1, FixSource.BALISE, unc, state, hyps=tuple(hyps))


def scan_cycle(aid: TopologyAid, fix: Fix, i0: int, tr) -> int:  # type: ignore[no-untyped-def]
    """The cycle of the full scan's first rule (the run's length: none)."""
    found = drained(aid._next_rule(fix, i0, tr))
    return tr.n if found is None else int(np.searchsorted(tr.t, found.t))


def test_bound_is_the_nearest_end_less_a_metre() -> None:
    """1 m a cycle from 100 m before a track's end: the bound waits until the travel d ≥ 100 − 1,
    cycle 99 (the scan's rule is at the end or beyond it); a second candidate 50 m from its
    track's begin: cycle 49."""
    n = net("junction")
    lines = track_lines(n)
    aid = TopologyAid(lines, MARGIN)
    tid = sorted(lines.lines)[0]
    length = lines[tid].length_m
    tr = travel(n, np.full(int(length) * 2, 10.0))
    fix = fix_of([Hypothesis(tid, length - 100.0, 1)])
    lb = aid.not_before(fix, 0, tr)
    assert lb == 99
    assert 100 <= scan_cycle(aid, fix, 0, tr) < tr.n
    both = fix_of([Hypothesis(tid, length - 100.0, 1), Hypothesis(tid, 50.0, -1)])
    assert aid.not_before(both, 0, tr) == 49  # the second candidate's begin, 50 m − 1 m away
    outside = fix_of([Hypothesis(tid, -3.0, 1)])
    assert aid.not_before(outside, 0, tr) == 0  # already beyond an end: no wait


@settings(max_examples=80, deadline=None)
@given(data=st.data())
def test_bound_never_after_the_scans_rule(data: st.DataObject) -> None:
    name = data.draw(st.sampled_from(["junction", "crossover", "station4", "double_slip"]))
    network = net(name)
    lines = track_lines(network)
    aid = TopologyAid(lines, MARGIN)
    ids = sorted(lines.lines)
    steps = st.tuples(st.integers(5, 200), st.sampled_from([-25.0, -5.0, 0.0, 0.0, 3.0, 12.0, 30.0]))
    pieces = data.draw(st.lists(steps, min_size=1, max_size=6))
    v = np.concatenate([np.full(k, s) for k, s in pieces])
    tr = travel(network, v, data.draw(st.sampled_from([1, -1])))
    hyps = []
    for _ in range(data.draw(st.integers(1, 3))):
        tid = data.draw(st.sampled_from(ids))
        length = lines[tid].length_m
        pos = data.draw(st.one_of(st.floats(-5.0, length + 5.0), st.sampled_from([0.0, 1.0, length - 0.5])))
        extra = data.draw(st.sampled_from([0.0, 0.0, 4.0]))
        hyps.append(Hypothesis(tid, pos, data.draw(st.sampled_from([1, -1])), extra))
    i_ref = data.draw(st.integers(0, tr.n - 1))
    fix = fix_of(hyps, float(tr.s[i_ref]), float(tr.d[i_ref]), data.draw(st.floats(0.0, 30.0)))
    for i0 in sorted({i_ref, data.draw(st.integers(i_ref, tr.n - 1)), tr.n - 1}):
        lb = aid.not_before(fix, i0, tr)
        assert i0 <= lb <= tr.n
        assert lb <= scan_cycle(aid, fix, i0, tr)


def test_engine_answers_identical_with_and_without_the_wait(sample_network_db, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """run_pipeline of the sample junction run: positions, events and fixes equal whether the
    topology aid waits for its bound or scans at every estimate; the bound did make it wait."""
    from cli.demo import sample_logs_dir
    from dbtools.database import read_network
    from fieldlogs.pipeline.config import PipelineConfig
    from fieldlogs.pipeline.run import run_pipeline
    from fieldlogs.runs.handle import read_run

    network = read_network(sample_network_db)
    real = TopologyAid.not_before
    waits: list[int] = []

    def counted(self: TopologyAid, fix: Fix, i0: int, tr) -> int:  # type: ignore[no-untyped-def]
        lb = real(self, fix, i0, tr)
        waits.append(lb - i0)
        return lb

    monkeypatch.setattr(TopologyAid, "not_before", counted)
    waited = run_pipeline(read_run(sample_logs_dir() / "sim-net-junction"), network, PipelineConfig())
    assert sum(w > 50 for w in waits) > len(waits) // 2
    monkeypatch.setattr(TopologyAid, "not_before", lambda self, fix, i0, tr: i0)
    at_once = run_pipeline(read_run(sample_logs_dir() / "sim-net-junction"), network, PipelineConfig())
    assert waited.positions.equals(at_once.positions)
    assert waited.events.equals(at_once.events)
    assert repr(waited.fixes) == repr(at_once.fixes)  # NaN km of ambiguous fixes: compared as text
    assert (waited.events["type"] == "switch_split").any()
