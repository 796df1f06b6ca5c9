"""IF samples → observation frames [S004 §2]: every T_epi of each frequency as one row.

Each row of ``radar_if`` is one (f1, f2) pair, f1 sampled at t and f2 at t + T_pri; pair
n of the run sits at slot n = round((t − t_first)·rate), rate = 1/(2·T_pri). Frame k holds
slots k·N … (k+1)·N − 1, N = round(T_epi·rate), so a run becomes two complex arrays
z_i[k, j] = i_i + j·q_i of shape (frames, N) by one reshape (or one scatter when slots are
missing, unsorted or repeated: the first row of a slot wins, empty slots stay 0 and count
as missing). Rows with a NaN in t or a sample are missing slots. Only whole frames are kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from schemas.radar import RadarParams

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex64]


@dataclass(frozen=True)
class Frames:
    """The frames of one run (or of a block of it)."""

    z1: ComplexArray
    """f1 samples, (frames, N), complex64."""
    z2: ComplexArray
    """f2 samples (each T_pri after its f1 sample)."""
    present: npt.NDArray[np.bool_] | None
    """(frames, N) True where the slot holds a sample; None when every slot does."""
    t_first: float
    """t of slot 0 [s]."""
    rate_hz: float

    @property
    def n_frames(self) -> int:
        return int(self.z1.shape[0])

    @property
    def n_per_frame(self) -> int:
        return int(self.z1.shape[1])

    @property
    def t_centre(self) -> FloatArray:
        """Frame centres [s]: the middle of its pairs (f1 at slot times, f2 T_pri later)."""
        n = self.n_per_frame
        k = np.arange(self.n_frames, dtype=np.float64)
        return np.asarray(self.t_first + (k * n + (n - 1) / 2.0) / self.rate_hz + 0.25 / self.rate_hz)

    @property
    def valid_share(self) -> FloatArray:
        if self.present is None:
            return np.ones(self.n_frames)
        return np.asarray(self.present.mean(axis=1, dtype=np.float64))

    def block(self, start: int, stop: int) -> Frames:
        """Frames start … stop − 1 (views, no copy)."""
        present = None if self.present is None else self.present[start:stop]
        first = self.t_first + start * self.n_per_frame / self.rate_hz
        return Frames(self.z1[start:stop], self.z2[start:stop], present, first, self.rate_hz)


def _complex(i: npt.ArrayLike, q: npt.ArrayLike) -> ComplexArray:
    out = np.empty(np.shape(i), dtype=np.complex64)
    out.real = i
    out.imag = q
    return out


def frame_samples(
    t: npt.ArrayLike,
    i1: npt.ArrayLike,
    q1: npt.ArrayLike,
    i2: npt.ArrayLike,
    q2: npt.ArrayLike,
    params: RadarParams,
) -> Frames:
    """Cut the samples of a run into frames of N = round(T_epi / (2·T_pri)) pairs."""
    t = np.asarray(t, dtype=np.float64)
    cols = [np.asarray(c, dtype=np.float32) for c in (i1, q1, i2, q2)]
    rate = params.sample_rate_hz
    n_per = params.samples_per_frame
    ok = np.isfinite(t)
    for c in cols:
        ok &= np.isfinite(c)
    if not ok.any():
        empty = np.zeros((0, n_per), dtype=np.complex64)
        return Frames(empty, empty.copy(), None, 0.0, rate)
    t_first = float(t[ok].min())
    slot = np.rint(np.where(ok, t - t_first, -1.0) * rate).astype(np.int64)
    n_frames = (int(slot[ok].max()) + 1) // n_per
    total = n_frames * n_per
    if ok.all() and len(t) >= total and np.array_equal(slot[:total], np.arange(total)):
        z1 = _complex(cols[0][:total], cols[1][:total]).reshape(n_frames, n_per)
        z2 = _complex(cols[2][:total], cols[3][:total]).reshape(n_frames, n_per)
        return Frames(z1, z2, None, t_first, rate)
    keep = np.flatnonzero(ok & (slot < total))
    slots, first = np.unique(slot[keep], return_index=True)  # first row (file order) of each slot
    rows = keep[first]
    z1f = np.zeros(total, dtype=np.complex64)
    z2f = np.zeros(total, dtype=np.complex64)
    z1f[slots] = _complex(cols[0][rows], cols[1][rows])
    z2f[slots] = _complex(cols[2][rows], cols[3][rows])
    present = np.zeros(total, dtype=bool)
    present[slots] = True
    shape = (n_frames, n_per)
    return Frames(z1f.reshape(shape), z2f.reshape(shape), present.reshape(shape), t_first, rate)
