"""The numba kernels are cached on disk and compiled ahead (issue 21): every ``@njit`` has
``cache=True``, and each kernel's ``warm()`` (run by ``make`` at install) compiles exactly
the specialisation the real code calls, so no command compiles on its first use. The
matching kernel's numpy twin (few fixes: no numba at all) gives the same numbers."""

from __future__ import annotations

import ast
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools.gis import match_kernel, match_numpy
from dbtools.gis.geometry import Projector
from dbtools.gis.matching import TrackIndex, track_index_for
from fieldlogs.simulate import radar
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.scenario import RadarIfCfg
from tests.fresh import fresh_python

ROOT = Path(__file__).resolve().parents[1]


def _njit_calls() -> list[tuple[str, ast.Call | ast.Name | ast.Attribute]]:
    found = []
    for path in sorted(p for pkg in ("cli", "dbtools", "fieldlogs", "schemas") for p in (ROOT / pkg).rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if "numba" not in text:
            continue
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                for dec in node.decorator_list:
                    target = dec.func if isinstance(dec, ast.Call) else dec
                    name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
                    if name in ("njit", "jit", "vectorize", "guvectorize", "cfunc"):
                        found.append((f"{path.relative_to(ROOT)}:{node.name}", dec))
    return found


def test_every_numba_kernel_is_cached_on_disk() -> None:
    kernels = _njit_calls()
    assert len(kernels) >= 4  # the matching kernel and its two helpers, the radar echo sum
    for where, dec in kernels:
        cached = isinstance(dec, ast.Call) and any(
            k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True for k in dec.keywords
        )
        assert cached, f"{where}: @njit without cache=True"


def test_matching_kernel_warm_covers_the_real_calls() -> None:
    match_kernel.warm()
    warmed = list(match_kernel.match_kernel.signatures)
    assert len(warmed) == 1
    index = track_index_for(build_network([demo_line()], Projector(9)))
    m = index.match_xy(index.x[::7] + 1.5, index.y[::7] - 2.0)
    assert len(m) and (m["distance_m"] <= 15.0).all()
    assert list(match_kernel.match_kernel.signatures) == warmed  # nothing compiled for the real call


def test_radar_kernel_warm_covers_the_real_calls() -> None:
    radar.warm()
    warmed = list(radar._echo_kernel.signatures)
    assert len(warmed) == 1
    cfg = RadarIfCfg()
    sigma = np.linspace(0.0, 5.0, 50)
    g = radar.Ground(sigma, np.zeros(50), np.zeros(50), np.ones(50, dtype=np.complex128))
    z = radar.echo(g, np.array([0.5, 1.0]), np.full(2, cfg.height_m), 1, cfg.f0_hz, cfg, radar.view(cfg))
    assert z.shape == (2,) and np.isfinite(z).all() and math.isfinite(float(np.abs(z).sum()))
    assert list(radar._echo_kernel.signatures) == warmed


@pytest.mark.parametrize("module", ["dbtools/gis/matching.py", "fieldlogs/simulate/simulator.py"])
def test_modules_that_read_a_db_or_simulate_do_not_import_numba(module: str) -> None:
    """numba is imported by the kernel modules only, when a kernel is first called."""
    tree = ast.parse((ROOT / module).read_text(encoding="utf-8"))
    top = [n for n in tree.body if isinstance(n, ast.Import | ast.ImportFrom)]
    names = {a.name for n in top if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module or "" for n in top if isinstance(n, ast.ImportFrom)}
    assert not {n for n in names if n.split(".")[0] == "numba" or n.endswith("match_kernel")}


@st.composite
def _lattice_tracks(draw: st.DrawFn) -> tuple[TrackIndex, np.ndarray, np.ndarray, float]:
    """1–4 tracks with vertices on a 5 m lattice (exact ties between segments and, with a
    repeated track, between tracks), sometimes a repeated vertex (a zero-length segment, as
    the index makes of an isolated point);
    fixes on a 0.5 m lattice near them, a few far away, a few NaN."""
    tracks = []
    for _ in range(draw(st.integers(1, 4))):
        if tracks and draw(st.booleans()):
            tracks.append(tracks[-1])  # the same geometry on another track: equal distances
            continue
        n = draw(st.integers(1, 25))
        steps = draw(
            st.lists(
                st.sampled_from([(1, 0), (0, 1), (1, 1), (2, -1), (-1, 1), (3, 0), (0, 0)]), min_size=n, max_size=n
            )
        )
        xy = np.cumsum(np.array([(draw(st.integers(-20, 20)), draw(st.integers(-20, 20))), *steps]), axis=0)
        tracks.append(5.0 * xy.astype(float))
    x, y, km, tid = [], [], [], []
    for t, pts in enumerate(tracks):
        seg = np.hypot(*np.diff(pts, axis=0).T)
        x.append(pts[:, 0])
        y.append(pts[:, 1])
        km.append(np.concatenate([[0.0], np.cumsum(seg)]))
        tid.append(np.full(len(pts), t))
    grid = SimpleNamespace(x=np.concatenate(x), y=np.concatenate(y), km=np.concatenate(km), tid=np.concatenate(tid))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n_fix = draw(st.integers(1, 60))
    pick = rng.integers(0, grid.x.size, n_fix)
    qx = grid.x[pick] + 0.5 * rng.integers(-40, 41, n_fix)
    qy = grid.y[pick] + 0.5 * rng.integers(-40, 41, n_fix)
    qx[rng.random(n_fix) < 0.05] = np.nan
    qy[rng.random(n_fix) < 0.05] += 1e4
    return _index_on(grid, len(tracks)), qx, qy, draw(st.sampled_from([3.0, 7.5, 15.0, 40.0]))


def _index_on(grid: SimpleNamespace, n_tracks: int) -> TrackIndex:
    """A TrackIndex on raw plane coordinates (no projection): vertices = the grid, cut
    between tracks only."""
    index = TrackIndex.__new__(TrackIndex)
    index.keys = [(f"L{t}", "D") for t in range(n_tracks)]
    index.x, index.y, index.km, index.vertex_track = grid.x, grid.y, grid.km, grid.tid
    nv = grid.x.size
    index.segment_ok = np.zeros(nv, dtype=bool)
    index.segment_ok[:-1] = grid.tid[1:] == grid.tid[:-1]
    index._segment_constants()
    return index


def _rows(parts: list[tuple[np.ndarray, ...]]) -> list[tuple[int, ...]]:
    """The rows as tuples of integers (floats as their bit patterns: −0.0 ≠ 0.0), sorted."""
    if not parts:
        return []
    cols = [np.concatenate(c) for c in zip(*parts, strict=True)]
    bits = [c.view(np.int64) if c.dtype == np.float64 else c.astype(np.int64) for c in cols]
    return sorted(zip(*(c.tolist() for c in bits), strict=True))


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_lattice_tracks(), st.booleans(), st.sampled_from([1, 3, 8192]))
def test_numpy_matching_equals_the_kernel_bit_for_bit(case, restrict, block) -> None:  # type: ignore[no-untyped-def]
    """Both candidate searches of TrackIndex.match_xy give the same rows, bit for bit (exact
    ties included), whatever the block size of the numpy path."""
    index, qx, qy, max_offset = case
    finite = np.flatnonzero(np.isfinite(qx) & np.isfinite(qy))
    cells = index._cells(max_offset + index.half_max_segment_m)
    ok = np.ones(len(index.keys), dtype=bool)
    if restrict:
        ok[::2] = False
    consts = (index.x, index.y, index._dx, index._dy, index._inv_len2, index.segment_ok, index.vertex_track, ok)
    old = match_numpy.BLOCK_FIXES
    match_numpy.BLOCK_FIXES = block
    try:
        ours = match_numpy.match_numpy(qx, qy, finite, *cells, *consts, max_offset**2)
    finally:
        match_numpy.BLOCK_FIXES = old
    kern, done = [], 0
    while done < finite.size:
        *part, done = match_kernel.match_kernel(qx, qy, finite, done, *cells, *consts, max_offset**2)
        kern.append(tuple(part))
    assert _rows([ours]) == _rows(kern)


def test_match_xy_takes_numpy_for_few_fixes_and_the_kernel_for_many() -> None:
    """A few fixes are matched without numba in a fresh process; the frames of both paths
    are equal, exactly (the choice only changes the time)."""
    code = (
        "import sys\nimport numpy as np\n"
        "from dbtools.gis.geometry import Projector\n"
        "from dbtools.gis.matching import track_index_for\n"
        "from fieldlogs.simulate.networks.synthetic import build_network, demo_line\n"
        "idx = track_index_for(build_network([demo_line()], Projector(9)))\n"
        "rng = np.random.default_rng(5)\n"
        "sel = rng.integers(0, idx.x.size, 3000)\n"
        "x, y = idx.x[sel] + rng.normal(0, 8, 3000), idx.y[sel] + rng.normal(0, 8, 3000)\n"
        "a = idx.match_xy(x, y)\n"
        "light = 'numba' not in sys.modules\n"
        "import dbtools.gis.matching as m\n"
        "m.NUMPY_MAX_FIXES = 0  # every match above it: the compiled kernel\n"
        "b = idx.match_xy(x, y)\n"
        "print(light, 'numba' in sys.modules, len(a) > 3000, a.equals(b))\n"
    )
    assert fresh_python(code).split() == ["True", "True", "True", "True"]


def test_a_days_gps_fixes_are_matched_without_numba_in_bounded_memory() -> None:
    """A 24 h run's GPS at 1 Hz (86,400 fixes; the threshold was 50,000) is matched by the numpy
    path: numba is not imported (≈ 190 MB of RSS and ≈ 0.5 s to load the kernel), the path's
    own peak stays below 150 MB (≈ 60 MB measured at 100,000 fixes), and the frame is the
    kernel's, exactly."""
    code = (
        "import sys\nfrom pathlib import Path\nimport numpy as np\n"
        "from dbtools.gis.geometry import Projector\n"
        "from dbtools.gis.matching import track_index_for\n"
        "from fieldlogs.simulate.networks.synthetic import build_network, demo_line\n"
        "def status(key):\n"
        "    line = [s for s in Path('/proc/self/status').read_text().splitlines() if s.startswith(key)]\n"
        "    return int(line[0].split()[1]) / 1024\n"
        "idx = track_index_for(build_network([demo_line()], Projector(9)))\n"
        "rng = np.random.default_rng(5)\n"
        "n = 86_400\n"
        "sel = rng.integers(0, idx.x.size, n)\n"
        "x, y = idx.x[sel] + rng.normal(0, 8, n), idx.y[sel] + rng.normal(0, 8, n)\n"
        "Path('/proc/self/clear_refs').write_text('5')  # VmHWM from here\n"
        "rss = status('VmRSS')\n"
        "a = idx.match_xy(x, y)\n"
        "rise = status('VmHWM') - rss\n"
        "light = 'numba' not in sys.modules\n"
        "import dbtools.gis.matching as m\n"
        "m.NUMPY_MAX_FIXES = 0\n"
        "b = idx.match_xy(x, y)\n"
        "print(light, rise < 150, len(a) > n, a.equals(b), round(rise))\n"
    )
    assert fresh_python(code).split()[:4] == ["True", "True", "True", "True"]


def test_numpy_matching_keeps_the_kernels_signed_zero() -> None:
    """On a zero-length segment (a repeated vertex) below-left of the fix's foot, u is
    max(−0.0, 0.0) = −0.0 in the kernel (Python's max keeps its first argument): the numpy
    path gives the same bits, not np.maximum's +0.0."""
    grid = SimpleNamespace(
        x=np.array([0.0, 0.0, 10.0]), y=np.zeros(3), km=np.array([0.0, 0.0, 10.0]), tid=np.zeros(3, int)
    )
    index = _index_on(grid, 1)
    q, fixes = np.array([-1.0]), np.array([0])
    cells = index._cells(15.0 + index.half_max_segment_m)
    ok = np.ones(1, dtype=bool)
    consts = (index.x, index.y, index._dx, index._dy, index._inv_len2, index.segment_ok, index.vertex_track, ok)
    ours = match_numpy.match_numpy(q, q, fixes, *cells, *consts, 225.0)
    *kern, _ = match_kernel.match_kernel(q, q, fixes, 0, *cells, *consts, 225.0)
    assert np.signbit(kern[3][0]) and ours[2][0] == kern[2][0] == 0
    assert _rows([ours]) == _rows([tuple(kern)])


def test_nearest_per_track_by_hand() -> None:
    """Per (fix, track) the smallest (distance², segment) — a segment met twice (from both of
    its vertices) counts once, an exact distance tie goes to the lower segment — then each
    fix's tracks nearest first (distance ties: lower segment first)."""
    fix = np.array([0, 0, 0, 0, 0, 1, 1, 1])
    track = np.array([0, 0, 0, 1, 1, 0, 1, 1])
    seg = np.array([5, 3, 3, 9, 8, 2, 7, 6])
    d2 = np.array([4.0, 4.0, 4.0, 1.0, 2.0, 3.0, 3.0, 5.0])
    kept, passes = match_numpy._nearest_per_track(fix, track, seg, d2, 2)
    got = sorted(zip(fix[kept].tolist(), passes.tolist(), seg[kept].tolist(), d2[kept].tolist(), strict=True))
    assert got == [(0, 0, 9, 1.0), (0, 1, 3, 4.0), (1, 0, 2, 3.0), (1, 1, 7, 3.0)]
    empty = np.zeros(0, dtype=np.int64)
    assert [a.size for a in match_numpy._nearest_per_track(empty, empty, empty, np.zeros(0), 2)] == [0, 0]


def test_candidate_segments_each_once() -> None:
    """A straight track, vertices every 10 m along x, cells of 10 m; a fix at x = 25 m sees
    vertices 1–3 (cells 1–3): segments 0 (reached only from vertex 1), 1, 2 (each from both
    of their vertices, kept once) and 3 (from vertex 3) — not 0 twice, nor 4."""
    x = np.arange(6) * 10.0 + 5.0
    y = np.full(6, 5.0)
    ok = np.ones(6, dtype=bool)
    ok[-1] = False
    side = 10.0
    order = np.argsort(match_numpy.cell_keys(x, y, side), kind="stable")
    keys, start = np.unique(match_numpy.cell_keys(x, y, side)[order], return_index=True)
    start = np.append(start, 6)
    row, pos, cx, cy = match_numpy._candidates(np.array([25.0]), np.array([5.0]), side, keys, start)
    assert sorted(order[pos].tolist()) == [1, 2, 3]
    tracks = np.zeros(6, dtype=np.int64)
    r, s = match_numpy._segments(row, order[pos], cx, cy, side, x, y, ok, tracks, np.ones(1, dtype=bool))
    assert sorted(s.tolist()) == [0, 1, 2, 3] and r.tolist() == [0, 0, 0, 0]
