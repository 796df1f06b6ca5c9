"""Doppler lines of each frame: window, FFT per frequency, noise floor, peaks, pairing,
sub-bin frequency and range from the f1/f2 phase difference [S004 §2].

For every frame (all frames of a block at once, as 2-D arrays):

1. **DC removal and window.** The frame mean m (a static echo: car body, mixer offset,
   the ground at standstill) is removed; the DC share N·|m|²/σ² is kept for the
   standstill test. Then a periodic Hann window w_n = ½ − ½·cos(2πn/N).
2. **FFT per frequency**, zero-padded to the next fast length N_fft ≥ N (``scipy.fft``,
   batched over frames): S_i[k], bin spacing rate/N_fft (rate = 1/(2·T_pri)); a reflection
   closing at radial speed V_m gives a line at f_d = 2·V_m/λ, positive for an approaching
   reflector (I + jQ keeps the sign).
3. **Noise floor (CFAR).** Per frame and frequency the median bin power over the whole
   spectrum (every 4th bin), divided by ln 2, estimates the mean noise power per bin (noise power in a bin
   is exponential, median = ln2·mean) — an order-statistic CFAR whose reference cells are
   the whole spectrum, valid because ground clutter fills far less than half the band.
   A bin is a peak when it is a local maximum of its spectrum above −ln(P_fa) × that floor.
4. **Pairing.** A line is an f1 peak with an f2 peak in the same or an adjacent bin,
   outside ± ``dc_guard_bins`` of 0 Hz; its SNR = (P1 + P2)/(floor1 + floor2), and the
   same ratio at the mirror bin −k is kept (ground moving past is one-sided in Doppler,
   vibration of the antenna is not).
5. **Sub-bin frequency.** With A the magnitude √(P1 + P2) at bins k−1, k, k+1, the Hann
   window's exact three-bin interpolation δ = 2(A₊ − A₋)/(A₋ + 2A₀ + A₊) gives
   f_d = (k + δ)·rate/N_fft and V_m = f_d·λ/2 (a bin is ΔV = λ/(2·T_epi), Table 1: 0.073 km/h).
6. **Range from the phase difference.** f_i's echo has phase −4π·f_i·R/c, and f2 is
   sampled T_pri after f1, which adds 2π·f_d·T_pri. Hence
   Δφ = arg(e^{j2π·f_d·T_pri}·Σ_{k−1..k+1} S1·S2*) = 4π·Δf·R/c (mod 2π) and
   R = c·Δφ/(4π·Δf), unambiguous to c/(2·Δf) (Table 1: 11.76 m). A line whose Doppler has
   wrapped past the Nyquist frequency is compensated with f_d − rate, off by π: its range
   comes out shifted by c/(4·Δf), which is how aliasing is recognised (``solve``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.framing import Frames
from schemas.radar import RadarParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


#: The noise floor is the median of every 4th bin (768 of 3072: its standard error ≈ 3.6 %,
#: ±0.15 dB on the threshold) — the median is the costliest step of the spectra.
FLOOR_STRIDE = 4


@dataclass(frozen=True)
class Spectra:
    """Spectra of a block of frames."""

    s1: npt.NDArray[np.complex64]
    """(frames, N_fft) spectrum of f1."""
    s2: npt.NDArray[np.complex64]
    p1: npt.NDArray[np.float32]
    """|S1|²."""
    p2: npt.NDArray[np.float32]
    floor1: FloatArray
    """Mean noise power per bin of f1, per frame."""
    floor2: FloatArray
    dc_snr: FloatArray
    """N·|m|²/σ² of the stronger frequency: the static echo's SNR."""
    bin_hz: float
    """Bin spacing rate / N_fft [Hz]."""


@dataclass(frozen=True)
class Lines:
    """Paired Doppler lines of a block, flat (one entry per line), frame-major order."""

    frame: IntArray
    bin: IntArray
    """Signed bin index (negative: receding)."""
    fd_hz: FloatArray
    v_m: FloatArray
    """Radial speed [m/s], + approaching."""
    range_m: FloatArray
    snr: FloatArray
    """(P1 + P2)/(floor1 + floor2), linear."""
    snr_mirror: FloatArray
    """The same at the mirror bin −k: a translation is one-sided, vibration is not."""

    def __len__(self) -> int:
        return len(self.frame)


def fft_length(n: int) -> int:
    import scipy.fft

    return int(scipy.fft.next_fast_len(n, real=False))


def hann(n: int) -> npt.NDArray[np.float32]:
    """Periodic Hann window ½ − ½·cos(2πj/n)."""
    return (0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)).astype(np.float32)


def _demean(
    z: npt.NDArray[np.complex64], present: npt.NDArray[np.bool_] | None
) -> tuple[npt.NDArray[np.complex64], npt.NDArray[np.complex128]]:
    """z − its mean over the present samples (missing ones stay 0), and the mean."""
    if present is None:
        m = z.mean(axis=1, dtype=np.complex128)
        return z - m[:, None].astype(np.complex64), m
    count = np.maximum(present.sum(axis=1), 1)
    m = z.sum(axis=1, dtype=np.complex128) / count
    return z - (m[:, None] * present).astype(np.complex64), m


def spectra(frames: Frames, cfg: RadarConfig) -> Spectra:
    """Steps 1–3 for every frame of ``frames``."""
    import scipy.fft

    n = frames.n_per_frame
    n_fft = fft_length(n)
    w = hann(n)
    out: list[object] = []
    dc = np.zeros(frames.n_frames)
    w2 = float(np.sum(w.astype(np.float64) ** 2))
    for z in (frames.z1, frames.z2):
        zd, m = _demean(z, frames.present)
        s = scipy.fft.fft(zd * w, n=n_fft, axis=1, workers=1).astype(np.complex64, copy=False)
        p = (s.real * s.real + s.imag * s.imag).astype(np.float32, copy=False)
        floor = np.median(p[:, ::FLOOR_STRIDE], axis=1).astype(np.float64) / math.log(2.0)
        sigma2 = np.maximum(floor / w2, 1e-30)  # noise variance of one sample
        dc = np.maximum(dc, n * np.abs(m) ** 2 / sigma2)
        out += [s, p, floor]
    s1, p1, f1, s2, p2, f2 = out
    return Spectra(s1, s2, p1, p2, f1, f2, dc, frames.rate_hz / n_fft)  # type: ignore[arg-type]


def peaks(p: npt.NDArray[np.float32], floor: FloatArray, pfa: float) -> npt.NDArray[np.bool_]:
    """Local maxima (circular) above −ln(pfa) × floor, per row."""
    left = np.roll(p, 1, axis=1)
    right = np.roll(p, -1, axis=1)
    thr = (-math.log(pfa) * floor)[:, None]
    return np.asarray((p > left) & (p >= right) & (p > thr))


def paired(sp: Spectra, cfg: RadarConfig) -> npt.NDArray[np.bool_]:
    """Step 4: f1 peaks with an f2 peak within one bin, outside the DC guard."""
    k1 = peaks(sp.p1, sp.floor1, cfg.pfa)
    k2 = peaks(sp.p2, sp.floor2, cfg.pfa)
    pair = k1 & (k2 | np.roll(k2, 1, axis=1) | np.roll(k2, -1, axis=1))
    g = cfg.dc_guard_bins
    pair[:, : g + 1] = False
    if g > 0:
        pair[:, -g:] = False
    return pair


def interpolate(a_m: FloatArray, a_0: FloatArray, a_p: FloatArray) -> FloatArray:
    """Step 5: offset δ of a Hann-windowed tone from bin 0 given |X| at bins −1, 0, +1."""
    den = a_m + 2.0 * a_0 + a_p
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(den > 0, 2.0 * (a_p - a_m) / den, 0.0)
    return np.clip(d, -1.0, 1.0)


def detect_lines(sp: Spectra, params: RadarParams, cfg: RadarConfig) -> Lines:
    """Steps 4–6: every paired line of the block with its Doppler, radial speed, range, SNR."""
    fi, k = np.nonzero(paired(sp, cfg))
    fi = fi.astype(np.int64)
    k = k.astype(np.int64)
    n_fft = sp.p1.shape[1]
    km, kp = (k - 1) % n_fft, (k + 1) % n_fft
    a = [np.sqrt(sp.p1[fi, j].astype(np.float64) + sp.p2[fi, j]) for j in (km, k, kp)]
    delta = interpolate(*a)
    signed = np.where(k >= n_fft // 2, k - n_fft, k)
    fd = (signed + delta) * sp.bin_hz
    cross = np.zeros(len(k), dtype=np.complex128)
    for j in (km, k, kp):
        cross += sp.s1[fi, j].astype(np.complex128) * np.conj(sp.s2[fi, j])
    cross *= np.exp(2j * np.pi * fd * params.t_pri_s)
    dphi = np.mod(np.angle(cross), 2.0 * np.pi)
    floors = sp.floor1[fi] + sp.floor2[fi]
    snr = (sp.p1[fi, k].astype(np.float64) + sp.p2[fi, k]) / floors
    mirror = (-k) % n_fft
    snr_mirror = (sp.p1[fi, mirror].astype(np.float64) + sp.p2[fi, mirror]) / floors
    return Lines(
        frame=fi,
        bin=signed.astype(np.int64),
        fd_hz=fd,
        v_m=fd * params.wavelength_m / 2.0,
        range_m=params.r_max_m * dphi / (2.0 * np.pi),
        snr=snr,
        snr_mirror=snr_mirror,
    )
