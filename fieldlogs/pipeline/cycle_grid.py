"""The cycle grid's arithmetic: which 100 ms cycle ``(t[k−1], t[k]]`` each sample falls in,
and the per-cycle means of sorted samples (``np.add.reduceat`` over contiguous runs).

Shared by :mod:`fieldlogs.pipeline.cycles` (whole streams) and
:mod:`fieldlogs.pipeline.block_means` (streams consumed block by block), which both build on
it without importing each other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def cycle_index(t_cycles: FloatArray, t_samples: FloatArray) -> npt.NDArray[np.intp]:
    """Cycle k of each sample, the cycle ``(t[k−1], t[k]]`` it falls in (n when after the last)."""
    return np.searchsorted(t_cycles, t_samples, side="left")


@dataclass(frozen=True)
class Segments:
    """Samples grouped by cycle (sorted samples: each cycle's are one contiguous run)."""

    inside: npt.NDArray[np.bool_] | None
    """Samples on the grid (before the last cycle's end); None: all of them."""
    cycle: npt.NDArray[np.intp]
    """Cycle of each run of samples."""
    starts: npt.NDArray[np.intp]
    """First sample of each run, among the samples inside."""
    counts: npt.NDArray[np.intp]
    """Samples in each run."""

    @property
    def sample_cycles(self) -> npt.NDArray[np.intp]:
        """Cycle of every sample inside (``cycle_index`` of those samples)."""
        out: npt.NDArray[np.intp] = np.repeat(self.cycle, self.counts)
        return out


def segments(idx: npt.NDArray[np.intp], n: int) -> Segments:
    """The :class:`Segments` of samples whose cycles are ``idx`` on a grid of ``n`` cycles."""
    inside = idx < n
    every = bool(inside.all())
    k = idx if every else idx[inside]
    if k.size == 0:
        empty = np.zeros(0, dtype=np.intp)
        return Segments(None if every else inside, empty, empty, empty)
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    counts = np.diff(np.r_[starts, k.size])
    return Segments(None if every else inside, k[starts], starts, counts)


def cycle_means(
    t_cycles: FloatArray,
    t_samples: FloatArray,
    values: FloatArray,
    idx: npt.NDArray[np.intp] | None = None,
    seg: Segments | None = None,
) -> FloatArray:
    """Mean of the samples in each cycle ``(t[k−1], t[k]]`` (NaN for empty cycles).

    Samples must be sorted by time (they are: the pipeline sorts its streams), so each
    cycle is a contiguous slice and ``np.add.reduceat`` sums it without scattering.
    ``seg`` (:func:`segments`, shared by the columns of one stream) saves recomputing the
    slices; non-finite values are left out of their cycle's mean.
    """
    n = t_cycles.size
    if seg is None:
        seg = segments(cycle_index(t_cycles, t_samples) if idx is None else idx, n)
    out = np.full(n, np.nan)
    means_into(out, seg, values)
    return out


def means_into(out: FloatArray, seg: Segments, values: FloatArray) -> None:
    """Write into ``out`` the mean of each run of ``seg`` over ``values`` (the samples of
    ``seg``, inside or not), non-finite values left out; cycles without a finite sample are
    left as they are. The arithmetic of :func:`cycle_means` (one ``np.add.reduceat`` per
    run of samples, divided by its count)."""
    vals = values if seg.inside is None else values[seg.inside]
    ok = np.isfinite(vals)
    if not ok.all():  # drop the bad samples: the runs change
        k = seg.sample_cycles[ok]
        vals = vals[ok]
        if k.size == 0:
            return
        starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
        out[k[starts]] = np.add.reduceat(vals, starts) / np.diff(np.r_[starts, k.size])
        return
    if seg.starts.size:
        out[seg.cycle] = np.add.reduceat(vals, seg.starts) / seg.counts
