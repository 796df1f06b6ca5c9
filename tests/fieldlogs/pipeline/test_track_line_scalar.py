"""The scalar paths the engine takes per GPS fix give the NumPy formulas' numbers exactly
(issue 31: the engine's cost, results unchanged): :meth:`TrackLine.point` and
:meth:`TrackLine.project` against the array formulas they replaced, and the ``candidates``
cells :func:`~fieldlogs.pipeline.claims.claims` makes at once against
the reference text (:mod:`tests.fieldlogs.pipeline.claims_reference`) cycle by cycle."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.claims import Entry, claims
from fieldlogs.pipeline.hypotheses import TrackLine
from fieldlogs.pipeline.types import FloatArray
from tests.fieldlogs.pipeline.claims_reference import candidates_text


def line(xy: FloatArray, cpos: FloatArray) -> TrackLine:
    return TrackLine("T", "", "", float(cpos[-1]), None, 0.0, 1, np.empty(0), np.empty(0), xy, cpos, (0.0, 0.0))


def point_np(tl: TrackLine, pos: float) -> tuple[float, float, float, float]:
    """The array formula of the centreline point and tangent."""
    p = min(max(pos, float(tl.cpos[0])), float(tl.cpos[-1]))
    j = int(np.clip(np.searchsorted(tl.cpos, p, side="right") - 1, 0, tl.cpos.size - 2))
    (x0, y0), (x1, y1) = tl.xy[j], tl.xy[j + 1]
    u = (p - float(tl.cpos[j])) / max(float(tl.cpos[j + 1] - tl.cpos[j]), 1e-9)
    dx, dy = x1 - x0, y1 - y0
    norm = max(math.hypot(dx, dy), 1e-9)
    return x0 + u * dx, y0 + u * dy, dx / norm, dy / norm


def project_np(tl: TrackLine, x: float, y: float, near: float, window_m: float) -> tuple[float, float]:
    """The array formula of the projection on the window's segments."""
    n = tl.cpos.size
    lo = max(int(np.searchsorted(tl.cpos, near - window_m, side="right")) - 1, 0)
    hi = min(int(np.searchsorted(tl.cpos, near + window_m, side="left")) + 1, n)
    if hi - lo < 2:
        return math.nan, math.nan
    a, b = tl.xy[lo : hi - 1], tl.xy[lo + 1 : hi]
    ab = b - a
    l2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    u = np.clip(((x - a[:, 0]) * ab[:, 0] + (y - a[:, 1]) * ab[:, 1]) / l2, 0.0, 1.0)
    fx, fy = a[:, 0] + u * ab[:, 0], a[:, 1] + u * ab[:, 1]
    j = int(np.argmin((x - fx) ** 2 + (y - fy) ** 2))
    c0, c1 = float(tl.cpos[lo + j]), float(tl.cpos[lo + j + 1])
    norm = max(math.sqrt(float(l2[j])), 1e-9)
    off = (-(x - float(fx[j])) * float(ab[j, 1]) + (y - float(fy[j])) * float(ab[j, 0])) / norm
    return c0 + float(u[j]) * (c1 - c0), off


def same(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return all(u == v or (math.isnan(u) and math.isnan(v)) for u, v in zip(a, b, strict=True))


def test_project_hand_computed() -> None:
    tl = line(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]), np.array([0.0, 2.0, 4.0]))
    assert tl.project(1.0, 1.0, 1.0, 5.0) == (1.0, 1.0)  # on the first segment, 1 m left
    assert tl.project(3.0, 1.5, 3.0, 5.0) == (3.5, -1.0)  # on the second, 1 m right of north
    assert all(map(math.isnan, tl.project(0.0, 0.0, 100.0, 5.0)))  # no segment within the window
    assert tl.point(3.0) == (2.0, 1.0, 0.0, 1.0)


coord = st.floats(-200.0, 200.0, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.tuples(coord, coord), min_size=2, max_size=12),
    st.lists(st.sampled_from([0.0, 0.5, 3.7, 20.0]), min_size=11, max_size=11),
    st.tuples(coord, coord),
    st.floats(-50.0, 300.0),
    st.sampled_from([0.0, 3.0, 25.0, math.inf]),
)
def test_scalar_paths_equal_the_array_formulas(
    pts: list[tuple[float, float]], gaps: list[float], p: tuple[float, float], near: float, window: float
) -> None:
    xy = np.array(pts, dtype=float)
    cpos = np.concatenate([[0.0], np.cumsum(gaps[: len(pts) - 1])])
    tl = line(xy, cpos)
    assert same(tl.project(p[0], p[1], near, window), project_np(tl, p[0], p[1], near, window))
    assert same(tl.project(p[0], p[1], math.nan, window), project_np(tl, p[0], p[1], math.nan, window))
    assert same(tl.point(near), point_np(tl, near))


def test_candidates_cells_equal_the_text_cycle_by_cycle() -> None:
    n = 6
    pos = np.array([1.0, 2.0004, math.nan, 4.0, 5.0, 6.0])
    every = np.ones(n, dtype=bool)
    ents = [
        Entry("A", pos, pos + 1000.0, np.full(n, 2.5), every, 1, ("L", "D")),
        Entry("B", pos + 10.0, np.full(n, math.nan), np.full(n, 2.5), np.array([0, 1, 1, 0, 1, 1], bool), -1, ("", "")),
        Entry("A", pos + 0.5, pos, np.full(n, 9.0), np.array([1, 1, 0, 0, 0, 1], bool), 1, ("L", "D")),
        Entry("C", pos - 3.0, pos - 3.0, np.full(n, math.inf), np.array([0, 0, 0, 0, 1, 1], bool), 1, ("L", "U")),
    ]
    cl = claims(ents)
    assert cl.ambiguous.tolist() == [False, True, True, False, True, True]
    for i in range(n):
        expected = candidates_text([e for e in ents if e.mask[i]], i) if cl.ambiguous[i] else None
        assert cl.text[i] == expected
    assert cl.text[1] == (
        '[{"track_id":"A","pos_m":2.0,"km_m":1002.0,"margin_m":2.5},'
        '{"track_id":"B","pos_m":12.0,"km_m":null,"margin_m":2.5}]'
    )
