"""Cycle means of a sampled stream fed block by block: the means of
:func:`fieldlogs.pipeline.cycles.cycle_means`, bit for bit, without the whole stream's
per-sample index arrays (a long run's 100 Hz IMU).

Cycle k holds the samples with t in ``(t[k−1], t[k]]`` (:func:`~fieldlogs.pipeline.cycles.cycle_index`).
Samples sorted by time (non-decreasing t; repeated values allowed) put each cycle's samples in
one contiguous run, so a stream may be cut into blocks anywhere: the samples of the last cycle
a block reaches are carried into the next block (a cycle split across two blocks is summed
from one contiguous array), every earlier cycle of the block is complete and is reduced as
:func:`~fieldlogs.pipeline.cycles.means_into` reduces it in the whole-array path — the same
``np.add.reduceat`` over the same finite values, divided by the same count — so each mean is
bit-identical. Samples after the last cycle are left out in both paths.

Unsorted input (t decreasing somewhere, inside a block or across two, or a NaN t) is
detected and ends the accumulation: :attr:`BlockCycleMeans.in_order` turns False and the
caller must use the whole-array path, which is what gives those samples their meaning today
(a cycle whose samples form several runs takes the last run's mean). The pipeline never gets
there: ``clean_stream`` sorts the streams and drops missing and repeated t first.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
import numpy.typing as npt

from fieldlogs.pipeline.cycle_grid import FloatArray, cycle_index, means_into, segments

IntArray = npt.NDArray[np.intp]
#: Samples per block when a stream in memory is consumed block by block (≈ 11 min at 100 Hz:
#: the per-sample index and masks of one block, ≈ 1 MB, instead of the whole run's).
BLOCK_ROWS = 1 << 16


class BlockCycleMeans:
    """Accumulates the cycle means of ``columns`` on the grid ``t_cycles`` from blocks of
    samples given in time order (module docstring)."""

    def __init__(self, t_cycles: FloatArray, columns: Sequence[str]) -> None:
        self.t_cycles = t_cycles
        self.columns = tuple(columns)
        self.means: dict[str, FloatArray] = {c: np.full(t_cycles.size, np.nan) for c in self.columns}
        self.in_order = True
        """False once a block broke the time order: the means are then not defined by blocks."""
        self._last_t = -np.inf
        self._carry_k: IntArray = np.zeros(0, dtype=np.intp)
        self._carry: dict[str, FloatArray] = {c: np.zeros(0) for c in self.columns}

    def add(self, t: FloatArray, values: Mapping[str, FloatArray]) -> None:
        """Take the next block: sample times ``t`` and each column's values at them."""
        if not self.in_order or t.size == 0:
            return
        if not (t[0] >= self._last_t and bool((t[1:] >= t[:-1]).all())):  # False on NaN too
            self.in_order = False
            self._carry_k = np.zeros(0, dtype=np.intp)
            self._carry = {}
            return
        self._last_t = float(t[-1])
        k = cycle_index(self.t_cycles, t)
        vals = {c: np.asarray(values[c], dtype=np.float64) for c in self.columns}
        if self._carry_k.size:
            k = np.concatenate([self._carry_k, k])
            vals = {c: np.concatenate([self._carry[c], vals[c]]) for c in self.columns}
        last = int(k[-1])
        # the last cycle reached may go on in the next block (none does beyond the grid)
        cut = k.size if last >= self.t_cycles.size else int(np.searchsorted(k, last, side="left"))
        self._carry_k = k[cut:].copy()
        self._carry = {c: vals[c][cut:].copy() for c in self.columns}
        self._reduce(k[:cut], {c: vals[c][:cut] for c in self.columns})

    def finish(self) -> dict[str, FloatArray] | None:
        """The cycle means (NaN where a cycle has no finite sample), None when the blocks
        were not in time order (then use :func:`~fieldlogs.pipeline.cycles.cycle_means`)."""
        if not self.in_order:
            return None
        self._reduce(self._carry_k, self._carry)
        self._carry_k = np.zeros(0, dtype=np.intp)
        self._carry = {c: np.zeros(0) for c in self.columns}
        return self.means

    def _reduce(self, k: IntArray, vals: Mapping[str, FloatArray]) -> None:
        """Means of the complete cycles ``k`` (each one run of samples) into :attr:`means`."""
        if k.size == 0:
            return
        seg = segments(k, self.t_cycles.size)  # once for the columns of the block
        for c in self.columns:
            means_into(self.means[c], seg, vals[c])


def means_by_blocks(
    t_cycles: FloatArray,
    n_samples: int,
    block: Callable[[int, int], tuple[FloatArray, Mapping[str, FloatArray]]],
    columns: Sequence[str],
    rows: int = BLOCK_ROWS,
) -> dict[str, FloatArray] | None:
    """Cycle means of ``n_samples`` samples read as ``block(start, stop)`` → (t, values) for
    consecutive row ranges of ``rows``; None when they are not in time order."""
    acc = BlockCycleMeans(t_cycles, columns)
    for start in range(0, n_samples, max(rows, 1)):
        t, values = block(start, min(start + rows, n_samples))
        acc.add(t, values)
        if not acc.in_order:
            return None
    return acc.finish()
