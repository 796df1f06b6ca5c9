"""Framing of radar_if rows: slots, whole frames, gaps, unsorted and repeated rows."""

from __future__ import annotations

import numpy as np
import pytest

from fieldlogs.radar.framing import frame_samples
from schemas.radar import RadarParams

# small frames: 1 kHz pairs (T_pri 0.5 ms), T_epi 10 ms → 10 pairs per frame
P = RadarParams(24.06e9, 12.75e6, 0.5e-3, 0.010, 0.8, 45.0, 7.5, 3.0)


def rows(n: int, t0: float = 2.0) -> dict[str, np.ndarray]:
    k = np.arange(n)
    return {"t": t0 + k / 1000.0, "i1": k * 1.0, "q1": -k * 1.0, "i2": k + 0.5, "q2": k - 0.5}


def test_rows_become_frames_of_n_pairs() -> None:
    assert P.samples_per_frame == 10
    d = rows(35)  # 3 whole frames, 5 pairs dropped
    fr = frame_samples(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], P)
    assert fr.z1.shape == (3, 10) and fr.present is None
    assert fr.z1[1, 3] == pytest.approx(13 - 13j) and fr.z2[2, 9] == pytest.approx(29.5 + 28.5j)
    # centre of frame 0: t0 + 4.5 ms (f1 instants) + T_pri/2 (f2 half a pair later)
    assert fr.t_centre == pytest.approx(2.0 + np.array([4.5, 14.5, 24.5]) / 1000 + 0.25e-3)
    assert fr.valid_share.tolist() == [1.0, 1.0, 1.0]


def test_unsorted_repeated_and_missing_rows() -> None:
    d = rows(30)
    order = np.r_[np.arange(30)[::-1], 3]  # reversed, row 3 repeated with other values
    cols = {k: v[order].copy() for k, v in d.items()}
    cols["i1"][-1] = 999.0
    cols["t"][order == 15] = np.nan  # pair 15 unusable
    fr = frame_samples(cols["t"], cols["i1"], cols["q1"], cols["i2"], cols["q2"], P)
    assert fr.z1.shape == (3, 10)
    assert fr.z1[0, 3] == pytest.approx(3 - 3j)  # the first row of a slot wins
    assert fr.present is not None and not fr.present[1, 5] and fr.z1[1, 5] == 0
    assert fr.valid_share.tolist() == [1.0, 0.9, 1.0]


def test_a_gap_leaves_empty_slots() -> None:
    d = rows(40)
    keep = (np.arange(40) < 12) | (np.arange(40) >= 18)
    t, i1, q1, i2, q2 = (d[k][keep] for k in ("t", "i1", "q1", "i2", "q2"))
    fr = frame_samples(t, i1, q1, i2, q2, P)
    assert fr.z1.shape == (4, 10)
    assert fr.valid_share.tolist() == [1.0, 0.4, 1.0, 1.0]


def test_blocks_are_views_with_their_own_times() -> None:
    d = {k: v if k == "t" else v.astype(np.float32) for k, v in rows(50).items()}
    fr = frame_samples(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], P)
    b = fr.block(2, 4)
    assert b.n_frames == 2 and b.t_centre == pytest.approx(fr.t_centre[2:4])
    assert np.shares_memory(b.i1, fr.i1) and np.shares_memory(fr.q2, d["q2"])


def test_nothing_usable_gives_no_frame() -> None:
    nan = np.full(5, np.nan)
    fr = frame_samples(nan, nan, nan, nan, nan, P)
    assert fr.n_frames == 0
