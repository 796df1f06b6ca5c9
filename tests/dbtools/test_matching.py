"""Map-matching to the 20 m GIS grid (SPEC §5.4): exact nearest segment per track against
brute force (hypothesis), km/offset truth on the synthetic demo line, breaks, restrictions."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools.gis.geometry import Projector
from dbtools.gis.matching import MATCH_COLUMNS, TrackIndex, track_index_for
from fieldlogs.simulate.networks.synthetic import TRACK_OFFSETS, build_network, demo_line
from tests.fresh import fresh_python

P = Projector(9)


@pytest.fixture(scope="module")
def demo():
    spec = demo_line()
    net = build_network([spec], P)
    return spec, net, track_index_for(net)


def grid_frame(tracks: dict[tuple[str, str], tuple[np.ndarray, np.ndarray, np.ndarray]]) -> pd.DataFrame:
    frames = []
    for (line, track), (x, y, km) in tracks.items():
        lon, lat = P.to_lonlat(x, y)
        frames.append(pd.DataFrame({"line_code": line, "track": track, "km_m": km, "lat": lat, "lon": lon}))
    return pd.concat(frames, ignore_index=True)


def brute(x: np.ndarray, y: np.ndarray, km: np.ndarray, ok: np.ndarray, qx: float, qy: float):
    """Every segment i → i+1 with ok[i], and every isolated point (both neighbouring
    segments cut) as a zero-length segment: (distance, km, signed offset) arrays."""
    lone = np.ones(x.size, dtype=bool)
    lone[:-1] &= ~ok
    lone[1:] &= ~ok
    ax, ay = np.concatenate([x[:-1][ok], x[lone]]), np.concatenate([y[:-1][ok], y[lone]])
    bx, by = np.concatenate([x[1:][ok], x[lone]]), np.concatenate([y[1:][ok], y[lone]])
    ka, kb = np.concatenate([km[:-1][ok], km[lone]]), np.concatenate([km[1:][ok], km[lone]])
    dx, dy = bx - ax, by - ay
    len2 = dx * dx + dy * dy
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.clip(np.where(len2 > 0, ((qx - ax) * dx + (qy - ay) * dy) / len2, 0.0), 0.0, 1.0)
    d = np.hypot(ax + u * dx - qx, ay + u * dy - qy)
    cross = dx * (qy - ay) - dy * (qx - ax)
    return d, ka + u * (kb - ka), np.where(cross >= 0, d, -d)


@st.composite
def networks(draw):
    """1–3 wiggly tracks (steps 5–60 m, turns up to ±70° per vertex, so polylines come back
    near themselves), km = length along the track, sometimes with a listed or unlisted jump."""
    tracks, breaks, valid = {}, [], {}
    n_tracks = draw(st.integers(1, 3))
    for k in range(n_tracks):
        n = draw(st.integers(2, 30))
        steps = np.array(draw(st.lists(st.floats(5.0, 60.0), min_size=n - 1, max_size=n - 1)))
        turns = np.array(draw(st.lists(st.floats(-1.2, 1.2), min_size=n - 1, max_size=n - 1)))
        h = draw(st.floats(-np.pi, np.pi)) + np.cumsum(turns)
        x0, y0 = draw(st.floats(-150, 150)), draw(st.floats(-150, 150))
        x = np.concatenate([[x0], x0 + np.cumsum(steps * np.cos(h))])
        y = np.concatenate([[y0], y0 + np.cumsum(steps * np.sin(h))])
        # the grid stores lat/lon: use the coordinates the index will see
        lon, lat = P.to_lonlat(x, y)
        x, y = P.to_xy(lon, lat)
        seg = np.hypot(np.diff(x), np.diff(y))
        km = draw(st.floats(0, 50_000)) + np.concatenate([[0.0], np.cumsum(seg)])
        ok = np.ones(n - 1, dtype=bool)
        key = (f"L{k % 2}", "D" if k < 2 else "U")
        if n > 3 and draw(st.booleans()):
            j = draw(st.integers(0, n - 2))
            km[j + 1 :] += draw(st.floats(50.0, 500.0))
            ok[j] = False
            if draw(st.booleans()):
                breaks.append({"line_code": key[0], "track": key[1], "km_from_m": km[j], "km_to_m": km[j + 1]})
        tracks[key] = (x, y, km)
        valid[key] = ok
    return tracks, valid, breaks


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(networks(), st.floats(3.0, 60.0), st.integers(0, 2**32 - 1))
def test_match_equals_brute_force(net, max_offset, seed):
    tracks, valid, breaks = net
    kb = pd.DataFrame(breaks, columns=["line_code", "track", "km_from_m", "km_to_m"])
    index = TrackIndex(grid_frame(tracks), P, kb)
    rng = np.random.default_rng(seed)
    allx = np.concatenate([v[0] for v in tracks.values()])
    ally = np.concatenate([v[1] for v in tracks.values()])
    pick = rng.integers(0, allx.size, 40)
    qx = allx[pick] + rng.uniform(-1.5, 1.5, 40) * max_offset
    qy = ally[pick] + rng.uniform(-1.5, 1.5, 40) * max_offset
    m = index.match_xy(qx, qy, max_offset_m=max_offset)
    assert tuple(m.columns) == MATCH_COLUMNS
    fix, tid, best = m["fix"].to_numpy(), m["track_id"].to_numpy(), m["best"].to_numpy()
    dist, km_m, off_m = m["distance_m"].to_numpy(), m["km_m"].to_numpy(), m["offset_m"].to_numpy()
    assert np.all(np.diff(fix) >= 0)
    got = {(int(f), int(t)): i for i, (f, t) in enumerate(zip(fix, tid, strict=True))}
    assert len(got) == len(m)  # one row per (fix, track)
    for q in range(qx.size):
        rows = np.flatnonzero(fix == q)
        if rows.size:
            assert best[rows].sum() == 1 and best[rows[0]] and dist[rows[0]] == dist[rows].min()
        for key, (x, y, km) in tracks.items():
            d, k, off = brute(x, y, km, valid[key], qx[q], qy[q])
            dmin = d.min()
            i = got.get((q, index.track_id(*key)))
            if dmin < max_offset - 1e-6:
                assert i is not None, (q, key, dmin)
                assert dist[i] == pytest.approx(dmin, abs=1e-6)
                ties = d <= dmin + 1e-6
                if np.ptp(k[ties]) < 1e-6:  # the nearest point is unique along the track
                    assert km_m[i] == pytest.approx(k[ties][0], abs=1e-6)
                    if dmin > 1e-6 and np.ptp(np.sign(off[ties])) == 0:
                        assert np.sign(off_m[i]) == np.sign(off[ties][0])
            elif dmin > max_offset + 1e-6:
                assert i is None, (q, key, dmin)


def test_noise_free_km_and_offset_on_curves(demo):
    spec, _, index = demo
    a = spec.alignment
    # points in the middle of every curve and on straights, on both tracks
    kms = [a.km(c.sc_m + c.arc_m * f) for c in a.curves for f in (0.1, 0.5, 0.9)]
    kms += list(np.linspace(a.km0 + 5, a.km_end - 5, 50))
    kms = np.asarray(kms, dtype=float)
    for track in ("D", "U"):
        x, y = a.xy(a.chainage(kms), TRACK_OFFSETS[track])
        lon, lat = P.to_lonlat(x, y)
        m = index.match(lat, lon)
        best = m[m["best"]]
        assert len(best) == kms.size
        assert (best["track"] == track).all()
        assert np.max(np.abs(best["km_m"].to_numpy() - kms)) < 0.5
        assert np.max(np.abs(best["offset_m"].to_numpy())) < 0.2  # chord sagitta ≤ 20²/(8R)
        other = m[~m["best"]]
        assert len(other) == kms.size  # the other track, 3.8 m away, is a candidate too
        # a point on D lies left of U (offset +3.8 from U); on U it lies right of D
        sign = 1.0 if track == "D" else -1.0
        assert np.allclose(other["offset_m"].to_numpy(), sign * 3.8, atol=0.25)


def test_offset_sign_left_of_increasing_km(demo):
    spec, _, index = demo
    a = spec.alignment
    s = a.chainage(np.array([2500.0, 6000.0, 9000.0]))
    for delta in (+1.0, -1.0):
        x, y = a.xy(s, TRACK_OFFSETS["D"] + delta)
        m = index.match_xy(x, y, line_code="0900", track="D")
        assert np.allclose(m["offset_m"], delta, atol=0.2)
    x, y = a.xy(s, TRACK_OFFSETS["U"] - 1.0)  # 1 m right of U
    m = index.match_xy(x, y)
    assert (m[m["best"]]["track"] == "U").all()
    assert np.allclose(m[m["best"]]["offset_m"], -1.0, atol=0.2)
    assert np.allclose(m[~m["best"]]["offset_m"], -4.8, atol=0.25)


def test_restriction_nan_and_empty(demo):
    spec, _, index = demo
    a = spec.alignment
    x, y = a.xy(a.chainage(np.array([3000.0, 3100.0])), TRACK_OFFSETS["D"])
    assert set(index.match_xy(x, y, track="U")["track"]) == {"U"}
    assert len(index.match_xy(x, y, line_code="9999")) == 0
    m = index.match_xy(np.array([np.nan, x[0]]), np.array([y[0], np.nan]))
    assert len(m) == 0 and tuple(m.columns) == MATCH_COLUMNS
    assert len(index.match([], [])) == 0
    far = index.match_xy(x + 500.0, y)
    assert len(far) == 0
    # unbounded projection onto a known track still works far away, exactly
    pr = index.project_onto(x + 200.0, y, "0900", "D")
    for i in range(2):
        t = index.track_id("0900", "D")
        sl = slice(index.pieces[index.pieces_of(t)[0]].start, index.pieces[index.pieces_of(t)[-1]].stop)
        d, k, _ = brute(index.x[sl], index.y[sl], index.km[sl], index.segment_ok[sl][:-1], x[i] + 200.0, y[i])
        assert pr.distance_m[i] == pytest.approx(d.min(), abs=1e-6)
        assert pr.km_m[i] == pytest.approx(k[np.argmin(d)], abs=1e-6)


def test_km_breaks_cut_pieces(demo):
    spec, net, _ = demo
    g = net.gis.copy()
    d = g["track"] == "D"
    jump = (g["km_m"] > 5000.0) & d
    g.loc[jump, "km_m"] += 700.0  # a km jump after 5k000 on D only (geometry continuous)
    listed = pd.DataFrame({"line_code": ["0900"], "track": ["D"], "km_from_m": [5000.0], "km_to_m": [5720.0]})
    for kb in (listed, None):  # listed, or detected from km step ≠ segment length
        index = TrackIndex(g, P, kb)
        assert len(index.pieces_of(index.track_id("0900", "D"))) == 2
        assert len(index.pieces_of(index.track_id("0900", "U"))) == 1
        a = spec.alignment
        x, y = a.xy(a.chainage(np.array([4990.0, 5030.0])), TRACK_OFFSETS["D"])
        m = index.match_xy(x, y, track="D")
        assert m["km_m"].iloc[0] == pytest.approx(4990.0, abs=0.5)
        assert m["km_m"].iloc[1] == pytest.approx(5030.0 + 700.0, abs=0.5)
        mid = index.match_xy(*a.xy(a.chainage(np.array([5010.0])), TRACK_OFFSETS["D"]), track="D")
        # inside the cut segment: projected to the nearer piece end, 10 m away
        assert mid["distance_m"].iloc[0] == pytest.approx(10.0, abs=0.2)


def test_missing_grid_point_is_not_a_cut_and_long_segments_are_exact(demo):
    _, net, _ = demo
    g = net.gis
    sparse = g[(g["km_m"] % 100 == 0) | (g["track"] == "U")]  # D every 100 m: densified
    index = TrackIndex(sparse, P)
    assert len(index.pieces) == 2
    assert index.half_max_segment_m < 12.6
    t = index.track_id("0900", "D")
    p = index.pieces[index.pieces_of(t)[0]]
    rng = np.random.default_rng(3)
    i = rng.integers(p.start, p.stop - 1, 200)
    qx = index.x[i] + rng.normal(0, 8, 200)
    qy = index.y[i] + rng.normal(0, 8, 200)
    m = index.match_xy(qx, qy, track="D", max_offset_m=30.0)
    sub = sparse[sparse["track"] == "D"].sort_values("km_m")
    ox, oy = P.to_xy(sub["lon"].to_numpy(), sub["lat"].to_numpy())
    okm = sub["km_m"].to_numpy()
    for _, row in m.iterrows():
        d, k, off = brute(ox, oy, okm, np.ones(ox.size - 1, dtype=bool), qx[row["fix"]], qy[row["fix"]])
        j = int(np.argmin(d))
        assert row["distance_m"] == pytest.approx(d[j], abs=1e-6)
        assert row["km_m"] == pytest.approx(k[j], abs=1e-6)
        assert row["offset_m"] == pytest.approx(off[j], abs=1e-6)


def test_index_is_cached_per_network(demo):
    _, net, index = demo
    assert track_index_for(net) is index
    other = build_network([demo_line()], P)
    assert track_index_for(other) is not index


def test_warm_up_outside_a_fork_server_leaves_the_kernel_alone() -> None:
    """A coordinator that forks its pool's workers imports fieldlogs.pipeline.warm too: it
    must not import the kernel's module (a match takes the kernel whenever that module is
    loaded, and every worker would then load numba on its first run)."""
    code = (
        "import sys, fieldlogs.pipeline.warm\n"
        "print('dbtools.gis.match_kernel' in sys.modules, 'numba' in sys.modules)\n"
    )
    assert fresh_python(code).split() == ["False", "False"]


def test_warm_up_loads_the_kernel_a_run_uses() -> None:
    """The fork-server warm-up (fieldlogs.pipeline.warm, imported after the server's
    fieldlogs.replay._server) loads the very overload a match uses: after it, matching the
    demo line adds no compiled signature."""
    code = (
        "import fieldlogs.replay._server, fieldlogs.pipeline.warm\n"
        "from dbtools.gis import match_kernel as k, matching as m\n"
        "from dbtools.gis.geometry import Projector\n"
        "from fieldlogs.simulate.networks.synthetic import build_network, demo_line\n"
        "before = list(k.match_kernel.signatures)\n"
        "idx = m.track_index_for(build_network([demo_line()], Projector(9)))\n"
        "x, y = idx.x[:50] + 3.0, idx.y[:50] - 2.0\n"
        "assert len(idx.match_xy(x, y)) > 0\n"
        "print(len(before), list(k.match_kernel.signatures) == before)\n"
    )
    assert fresh_python(code).split() == ["1", "True"]
