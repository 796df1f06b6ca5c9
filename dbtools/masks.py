"""Runs of True in a boolean mask: the one place the suite finds and merges them.

A *run* is a maximal slice ``mask[start:end]`` of True values; :func:`true_runs` returns the
starts and the exclusive ends of all runs in order, from the edges of the mask padded with
False at both ends: ``d = diff([0, mask, 0])``, starts where ``d = +1``, ends where ``d = −1``
(so a run reaching the last sample ends at ``len(mask)``). Used for GNSS outages, slip
episodes, curvature crossings (feature points), standstills, alarm episodes, spans of two
units' disagreement, IMU gaps and OSM node runs with coordinates.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

IntArray = npt.NDArray[np.int64]


def true_runs(mask: npt.ArrayLike) -> tuple[IntArray, IntArray]:
    """(starts, ends exclusive) of every run of True in ``mask``, in order; both empty
    when the mask holds no True."""
    d = np.diff(np.asarray(mask, dtype=np.int8), prepend=np.int8(0), append=np.int8(0))
    return np.flatnonzero(d == 1).astype(np.int64), np.flatnonzero(d == -1).astype(np.int64)


def run_around(mask: npt.ArrayLike, i: int) -> tuple[int, int]:
    """First and last index (inclusive) of the run of True in ``mask`` that holds index ``i``
    (``mask[i]`` True): the run widened from ``i`` to the nearest False on each side."""
    m = np.asarray(mask, dtype=bool)
    off_before, off_after = np.flatnonzero(~m[:i]), np.flatnonzero(~m[i + 1 :])
    a = int(off_before[-1]) + 1 if off_before.size else 0
    b = i + int(off_after[0]) if off_after.size else m.size - 1
    return a, b


def merge_runs(starts: IntArray, ends: IntArray, x: npt.NDArray[np.float64], gap: float) -> tuple[IntArray, IntArray]:
    """Runs of :func:`true_runs` merged where they are close: a run joins the previous one
    when ``x[start] − x[previous end − 1] < gap`` (``x`` the abscissa of the samples: travel,
    km or time, non-decreasing), as a chain (several close runs become one). A gap that is
    not a number (NaN in ``x``) does not merge."""
    if starts.size == 0:
        return starts, ends
    keep = np.concatenate([[True], ~(x[starts[1:]] - x[ends[:-1] - 1] < gap)])
    first = np.flatnonzero(keep)
    return starts[first], np.concatenate([ends[first[1:] - 1], ends[-1:]])


def sign_runs(
    values: npt.NDArray[np.float64], x: npt.NDArray[np.float64], level: float, merge: float
) -> list[tuple[int, int, int]]:
    """(start, end exclusive, sign) of every run where ``sign · value ≥ level`` (NaN counts as
    below), the runs of +1 first, then those of −1, each in order and merged by
    :func:`merge_runs` over ``x`` with ``merge``: the curvature crossings of a curve
    (κ ≥ κ_lo turning left, κ ≤ −κ_lo turning right) with the chatter of noise merged."""
    out: list[tuple[int, int, int]] = []
    for sgn in (1, -1):
        starts, ends = merge_runs(*true_runs(np.nan_to_num(sgn * values, nan=-np.inf) >= level), x, merge)
        out += [(s, e, sgn) for s, e in zip(starts.tolist(), ends.tolist(), strict=True)]
    return out
