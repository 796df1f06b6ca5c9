"""IF samples → observation frames [S004 §2]: every T_epi of each frequency as one row.

Each row of ``radar_if`` is one (f1, f2) pair, f1 sampled at t and f2 at t + T_pri; pair
n of the run sits at slot n = round((t − t_first)·rate), rate = 1/(2·T_pri). Frame k holds
slots k·N … (k+1)·N − 1, N = round(T_epi·rate), so a run becomes four (frames, N) arrays
by one reshape — views, no copy — (or one scatter when slots are missing, unsorted or
repeated: the first row of a slot wins, empty slots stay 0 and count as missing), and
z_i = i_i + j·q_i is built block by block. Rows with a NaN in t or a sample are missing
slots. Only whole frames are kept.

The samples are first put in the one convention the rest of the chain assumes, from the
run.json ``radar`` block: i ← I/full_scale, q ← q_sign·Q/full_scale (``RadarParams.q_sign``:
−1 when the recorder's quadrature channel has the other sign, ``iq_convention = "i-jq"``,
so that z = I − jQ; conjugating z mirrors the spectrum, f_d → −f_d, and the f1–f2 phase
difference, Δφ → −Δφ, of S004 eq. 1's range R = c·Δφ/(4π·Δf)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from schemas.radar import RadarParams

FloatArray = npt.NDArray[np.float64]
FloatArray32 = npt.NDArray[np.float32]
ComplexArray = npt.NDArray[np.complex64]


@dataclass(frozen=True)
class Frames:
    """The frames of one run (or of a block of it): the four sample columns as (frames, N)
    float32 arrays — views of the input when every slot is filled in order."""

    i1: FloatArray32
    q1: FloatArray32
    i2: FloatArray32
    """f2 samples (each T_pri after its f1 sample)."""
    q2: FloatArray32
    present: npt.NDArray[np.bool_] | None
    """(frames, N) True where the slot holds a sample; None when every slot does."""
    t_first: float
    """t of slot 0 [s]."""
    rate_hz: float

    @property
    def z1(self) -> ComplexArray:
        """f1 as i1 + j·q1, complex64 (built on access: take it of a block)."""
        return _complex(self.i1, self.q1)

    @property
    def z2(self) -> ComplexArray:
        return _complex(self.i2, self.q2)

    @property
    def n_frames(self) -> int:
        return int(self.i1.shape[0])

    @property
    def n_per_frame(self) -> int:
        return int(self.i1.shape[1])

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
        i1, q1, i2, q2 = (c[start:stop] for c in (self.i1, self.q1, self.i2, self.q2))
        return Frames(i1, q1, i2, q2, present, first, self.rate_hz)


def _complex(i: npt.ArrayLike, q: npt.ArrayLike) -> ComplexArray:
    out = np.empty(np.shape(i), dtype=np.complex64)
    out.real = i
    out.imag = q
    return out


def _regular(t: FloatArray, rate: float, chunk: int = 1 << 20) -> bool:
    """Every row on its own slot, in order: |t_n − (t_0 + n/rate)| < ¼ slot (checked in chunks)."""
    t0 = float(t[0])
    for start in range(0, len(t), chunk):
        seg = t[start : start + chunk]
        expect = t0 + (start + np.arange(len(seg), dtype=np.float64)) / rate
        if not bool((np.abs(seg - expect) < 0.25 / rate).all()):  # NaN fails too
            return False
    return True


def frame_samples(
    t: npt.ArrayLike,
    i1: npt.ArrayLike,
    q1: npt.ArrayLike,
    i2: npt.ArrayLike,
    q2: npt.ArrayLike,
    params: RadarParams,
) -> Frames:
    """Cut the samples of a run into frames of N = round(T_epi / (2·T_pri)) pairs, in FS and
    the ``i+jq`` convention (module docstring)."""
    t = np.asarray(t, dtype=np.float64)
    cols = [np.asarray(c, dtype=np.float32) for c in (i1, q1, i2, q2)]
    if params.full_scale != 1.0 or params.q_sign != 1.0:  # else keep the views (no copy)
        gains = (1.0, params.q_sign, 1.0, params.q_sign)
        cols = [(c * np.float32(g / params.full_scale)).astype(np.float32) for c, g in zip(cols, gains, strict=True)]
    rate = params.sample_rate_hz
    n_per = params.samples_per_frame
    if len(t) >= n_per and _regular(t, rate) and all(bool(np.isfinite(c).all()) for c in cols):
        n_frames = len(t) // n_per
        total = n_frames * n_per
        i1v, q1v, i2v, q2v = (c[:total].reshape(n_frames, n_per) for c in cols)
        return Frames(i1v, q1v, i2v, q2v, None, float(t[0]), rate)
    ok = np.isfinite(t)
    for c in cols:
        ok &= np.isfinite(c)
    if not ok.any():
        e = np.zeros((0, n_per), dtype=np.float32)
        return Frames(e, e, e, e, None, 0.0, rate)
    t_first = float(t[ok].min())
    slot = np.rint(np.where(ok, t - t_first, -1.0) * rate).astype(np.int64)
    n_frames = (int(slot[ok].max()) + 1) // n_per
    total = n_frames * n_per
    keep = np.flatnonzero(ok & (slot < total))
    slots, first = np.unique(slot[keep], return_index=True)  # first row (file order) of each slot
    rows = keep[first]
    shape = (n_frames, n_per)
    filled = []
    for c in cols:
        full = np.zeros(total, dtype=np.float32)
        full[slots] = c[rows]
        filled.append(full.reshape(shape))
    present = np.zeros(total, dtype=bool)
    present[slots] = True
    return Frames(filled[0], filled[1], filled[2], filled[3], present.reshape(shape), t_first, rate)
