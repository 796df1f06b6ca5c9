"""Clock offsets between a run's streams (issue 15): one check for ``logs check`` and the pipeline.

Every stream carries its own recorder's clock; the tacho's is the run's time base (its rows
are the onboard 100 ms cycles). A recorder whose clock runs ``L`` seconds **late** writes
``t = t_true + L`` (its t is larger than the truth: ``L > 0``); an early one ``L < 0``. The
offset is seen by cross-correlating a quantity both the stream and the tacho measure:

* **IMU**: a_x turned to the travel frame by the cab direction, against the pulse
  acceleration A_p = dv/dt of the tacho's speed (centred differences: the two respond together,
  lag 0 in the simulator; the SPEC's 300 ms pulse delay belongs to the odometry's trailing
  filters and lies inside the tolerance), so the clock offset is the measured lag;
* **GPS**: the speed over ground (``speed_mps`` where logged, else the distance between
  consecutive fixes over their time step, placed at the step's midpoint) against the tacho's
  speed. GPS positions then would be matched ``L·v`` behind the train.

Both signals are resampled onto a common grid of ``step_s`` — the tacho's by linear
interpolation, the stream's by its mean over each step (:func:`step_means`: the IMU's 100 Hz
samples averaged, not one in ten picked) — averaged over ``SMOOTH_S`` and high-passed (minus
their centred ``highpass_s`` mean: grade, biases and the mean speed carry no timing). With
r(t) the reference (tacho) and x(t) the stream,

    ρ(ℓ) = corr(r(t), x(t + ℓ)),  ℓ = j·step_s, |ℓ| ≤ max_lag_s,

over the grid points where both exist (all lags at once by FFT); the lag is the best ℓ refined
by the parabola through ρ at the best grid value and its two neighbours (x(t + L) = r(t) for a
stream L late), after robust passes that leave out what does not fit at the lag found (slips,
GPS multipath). The run is cut into 120 s blocks; its L̂ is the median of the blocks' lags and
σ = 1.4826·MAD/√n their spread. The estimate is *determined* when ρ ≥ ``min_corr``, at least
``min_span_s`` of motion went into it, the peak lies inside the range (not at ±max_lag_s) and
σ is at most half the tolerance. A determined offset beyond ``tolerance_s`` is reported
(``log.clock_offset``, the same finding ``logs check`` and ``run`` give); the pipeline then
moves the stream's t back by L̂ (the odometry's pulse-delay search takes up the last ±0.3 s of
the IMU; a GPS fix is worth 10 m: 0.1 s of residual at 30 m/s is 3 m). An offset within the
tolerance is not corrected: the feature-point corrections, the one aid that places the train
by IMU timing (the curve seen on the gyro), hold ``feature.clock_budget_s`` × speed for it.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.pipeline.block_means import BLOCK_ROWS
from fieldlogs.pipeline.config import ClockConfig
from fieldlogs.pipeline.cycles import cab_signs
from fieldlogs.quality.limits import masked
from fieldlogs.runs.handle import Run
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.units import metres_per_pulse
from schemas.vehicle import ANY_WHEEL_DIAMETER_M
from schemas.vehicle import TEETH_RANGE as TEETH

FloatArray = npt.NDArray[np.float64]

#: Both signals are averaged over this long before the correlation [s] (the GPS' 1 Hz steps).
SMOOTH_S = 1.0
#: Speed below which a grid point counts as standing (not motion evidence) [m/s].
MOVING_MPS = 1.0
#: Passes that leave out the grid points whose residual at the lag found is beyond
#: ROBUST_Z robust σ (slips and slides: the wheel's speed is not the ground's).
ROBUST_PASSES = 3
ROBUST_Z = 3.0
#: A block counts when the reference moved for at least this share of it.
MIN_BLOCK_MOVING = 0.25
#: An offset is determined when its σ is at most this share of the tolerance.
SIGMA_SHARE = 0.5
#: Earth radius for the local plane of consecutive GPS fixes [m].
EARTH_R_M = 6_371_000.0


@dataclass(frozen=True)
class Lag:
    """A cross-correlation lag estimate (module docstring)."""

    lag_s: float
    """x(t + lag) = r(t): + the stream is late (its t larger than the reference's) [s]."""
    corr: float
    """ρ at the peak."""
    moving_s: float
    """Time in motion the estimate saw [s]."""
    at_edge: bool
    """The peak is at the end of the searched range (a larger offset, or none found)."""
    sigma_s: float = np.inf
    """σ of the lag from the spread of its blocks (inf: fewer than 3 blocks) [s]."""
    blocks: int = 1


@dataclass(frozen=True)
class ClockOffset:
    """A stream's clock offset against the tacho."""

    stream: str
    offset_s: float
    """+ late (t larger than the truth), − early [s]."""
    sigma_s: float
    corr: float
    determined: bool
    beyond_tolerance: bool
    from_t: float | None = None
    """Set when a window of a long run could not determine its own offset and took this one,
    determined on the window starting at this t (:mod:`fieldlogs.pipeline.windows`)."""

    @property
    def message(self) -> str:
        way = "late" if self.offset_s > 0 else "early"
        where = "" if self.from_t is None else f", determined on the part from t = {self.from_t:.0f} s"
        return (
            f"{self.stream} clock {abs(self.offset_s):.2f} s {way} against the tacho "
            f"(cross-correlation ρ {self.corr:.2f}{where}; t of this stream is offset — the pipeline moves it back)"
        )


def _smooth_hp(x: FloatArray, step_s: float, highpass_s: float) -> FloatArray:
    """``x`` averaged over SMOOTH_S minus its centred ``highpass_s`` mean (NaN kept out)."""
    ok = np.isfinite(x)
    z = np.where(ok, x, 0.0)

    def centred(v: FloatArray, width_s: float) -> FloatArray:
        w = max(round(width_s / step_s), 1)
        kernel = np.ones(w)
        num = np.convolve(v, kernel, mode="same")
        den = np.convolve(ok.astype(float), kernel, mode="same")
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(den > 0, num / den, np.nan)

    s = centred(z, SMOOTH_S)
    s = np.where(ok, s, np.nan)
    base = centred(np.nan_to_num(s), highpass_s)
    return np.asarray(s - base, dtype=float)


def estimate_lag(
    t_ref: FloatArray,
    r: FloatArray,
    t_x: FloatArray,
    x: FloatArray,
    *,
    max_lag_s: float,
    step_s: float = 0.1,
    highpass_s: float = 30.0,
    block_s: float = 120.0,
    weight: FloatArray | None = None,
) -> Lag | None:
    """Lag of ``x`` (sampled at ``t_x``) behind ``r`` (at ``t_ref``): module docstring.

    The run is cut into blocks of ``block_s`` (at least one); each block's lag is the
    correlation peak (:func:`block_lag`) and the run's is their median, with the spread
    1.4826·MAD/√n of the block lags as its σ — one stretch of multipath or a slip that the
    robust passes miss moves one block, not the run's estimate. ``weight`` (on ``t_ref``, 0/1)
    marks the reference samples that count (e.g. moving); None when the two do not overlap by
    more than the searched range."""
    ok_r, ok_x = np.isfinite(t_ref) & np.isfinite(r), np.isfinite(t_x) & np.isfinite(x)
    t_ref, r = t_ref[ok_r], r[ok_r]
    if not ok_x.all():  # a long stream all finite (the usual case) is not copied
        t_x, x = t_x[ok_x], x[ok_x]
    del ok_x
    w_ref = np.ones(t_ref.size) if weight is None else np.asarray(weight, dtype=float)[ok_r]
    if t_ref.size < 10 or t_x.size < 10:
        return None
    t0, t1 = max(t_ref[0], t_x[0] - max_lag_s), min(t_ref[-1], t_x[-1] - max_lag_s)
    if t1 - t0 <= 2 * max_lag_s:
        return None
    nb = max(int((t1 - t0) // block_s), 1)
    edges = np.linspace(t0, t1, nb + 1)
    lags: list[Lag] = []
    for (a, b), sel in zip(itertools.pairwise(edges), block_rows(t_ref, edges), strict=True):
        lag = block_lag(
            t_ref[sel], r[sel], t_x, x, max_lag_s=max_lag_s, step_s=step_s, highpass_s=highpass_s, weight=w_ref[sel]
        )
        if lag is not None and lag.moving_s >= MIN_BLOCK_MOVING * (b - a):
            lags.append(lag)
    if not lags:
        return None
    v = np.array([g.lag_s for g in lags])
    med = float(np.median(v))
    sigma = 1.4826 * float(np.median(np.abs(v - med))) / np.sqrt(v.size) if v.size >= 3 else np.inf
    return Lag(
        med,
        float(np.median([g.corr for g in lags])),
        float(sum(g.moving_s for g in lags)),
        sum(g.at_edge for g in lags) * 2 > len(lags),
        sigma,
        len(lags),
    )


def block_rows(t: FloatArray, edges: FloatArray) -> Iterator[slice | npt.NDArray[np.bool_]]:
    """The rows of ``t`` in each block [a, b] of consecutive ``edges``, both ends included —
    those of the mask ``(t >= a) & (t <= b)``. Where ``t`` is sorted (the tacho's after
    clean_stream, the pipeline's case) they are one slice, its ends found by binary search:
    O(block) per block, where the mask over the whole 10 Hz reference made the clock check
    O(run²/block). Unsorted (or with a NaN, which no comparison orders), the mask."""
    if bool((t[1:] >= t[:-1]).all()):
        lo = np.searchsorted(t, edges[:-1], side="left")  # first t >= a
        hi = np.searchsorted(t, edges[1:], side="right")  # past the last t <= b
        for i, j in zip(lo.tolist(), hi.tolist(), strict=True):
            yield slice(i, max(i, j))
        return
    for a, b in itertools.pairwise(edges):
        yield (t >= a) & (t <= b)


def block_lag(
    t_ref: FloatArray,
    r: FloatArray,
    t_x: FloatArray,
    x: FloatArray,
    *,
    max_lag_s: float,
    step_s: float = 0.1,
    highpass_s: float = 30.0,
    weight: FloatArray | None = None,
) -> Lag | None:
    """The correlation-peak lag of one stretch (module docstring), after ROBUST_PASSES passes
    that leave out the grid points whose residual at the lag found is beyond ROBUST_Z robust σ
    (slips and slides: the wheel's speed is not the ground's; GPS multipath)."""
    if t_ref.size < 10:
        return None
    m = round(max_lag_s / step_s)
    g = np.arange(t_ref[0], t_ref[-1], step_s)
    if m < 1 or g.size < 10:
        return None
    gx = np.arange(g[0] - m * step_s, g[-1] + (m + 0.5) * step_s, step_s)[: g.size + 2 * m]
    rr = _smooth_hp(np.interp(g, t_ref, r), step_s, highpass_s)
    xx = _smooth_hp(step_means(t_x, x, gx, step_s), step_s, highpass_s)
    use = np.isfinite(rr)
    if weight is not None:
        use &= np.interp(g, t_ref, weight) > 0.5
    moving_s = float(use.sum()) * step_s
    if use.sum() < 10:
        return None
    rho = _rho(rr, xx, use, m)
    for _ in range(ROBUST_PASSES):
        if not np.isfinite(rho).any():
            return None
        k = int(np.nanargmax(rho))
        xs = xx[k : k + g.size]
        sel = use & np.isfinite(xs)
        beta = float(np.dot(rr[sel], xs[sel])) / max(float(np.dot(xs[sel], xs[sel])), 1e-300)
        e = np.abs(rr - beta * xs)
        mad = float(np.median(e[sel])) if sel.any() else 0.0
        keep = use & ~(e > ROBUST_Z * 1.4826 * mad)
        if keep.sum() < 10 or (keep == use).all():
            break
        use = keep
        rho = _rho(rr, xx, use, m)
    if not np.isfinite(rho).any():
        return None
    k = int(np.nanargmax(rho))
    frac = 0.0
    if 0 < k < 2 * m and np.isfinite(rho[k - 1]) and np.isfinite(rho[k + 1]):
        c = rho[k - 1] - 2.0 * rho[k] + rho[k + 1]
        frac = 0.5 * (rho[k - 1] - rho[k + 1]) / c if c < 0 else 0.0
    return Lag((k - m + frac) * step_s, float(rho[k]), moving_s, k in (0, 2 * m))


def step_means(t: FloatArray, x: FloatArray, g: FloatArray, step_s: float) -> FloatArray:
    """Means of ``x`` (linear between its samples at ``t``) over [g − step/2, g + step/2]:
    the difference of its running trapezoid integral at the two ends over ``step_s``; NaN
    where the window reaches beyond ``t``. A stream sampled faster than the grid (the IMU's
    100 Hz) is averaged, not point-sampled: its noise then enters the grid by 1/√(samples
    per step), not whole."""
    if t.size < 2 or g.size == 0:
        return np.full(g.size, np.nan)
    h = 0.5 * step_s
    lo, hi = g - h, g + h
    # only the samples that bracket the grid's windows (a block's, not the whole run's: the
    # integral over the whole stream per block made the clock check quadratic in run length);
    # the kept end samples bracket the first and last window as before, so the NaN rule holds
    i0 = max(int(np.searchsorted(t, lo.min(), side="right")) - 1, 0)
    i1 = min(int(np.searchsorted(t, hi.max(), side="left")) + 1, t.size)
    t, x = t[i0:i1], x[i0:i1]
    if t.size < 2:
        return np.full(g.size, np.nan)
    area = np.concatenate(([0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(t))))
    out = (np.interp(hi, t, area) - np.interp(lo, t, area)) / step_s
    return np.where((lo >= t[0]) & (hi <= t[-1]), out, np.nan)


def _rho(rr: FloatArray, xx: FloatArray, use: npt.NDArray[np.bool_], m: int) -> FloatArray:
    """ρ(ℓ) for ℓ = (j − m)·step, j = 0 … 2m, with x at g + ℓ being ``xx[j : j + n]``, over
    the points where ``use`` and both signals are finite: the six sums of the correlation
    coefficient (count, Σr, Σx, Σr², Σx², Σrx over each lag's common points) as valid-mode
    cross-correlations by FFT — O(n log n) for all lags at once."""
    n = rr.size
    u = use & np.isfinite(rr)
    v = np.isfinite(xx)
    r0, x0 = np.where(u, rr, 0.0), np.where(v, xx, 0.0)
    size = 1 << int(np.ceil(np.log2(n + xx.size)))
    fx = [np.fft.rfft(c, size) for c in (v.astype(float), x0, x0 * x0)]
    fr = [np.fft.rfft(c[::-1], size) for c in (u.astype(float), r0, r0 * r0)]

    def corr(i: int, j: int) -> FloatArray:  # Σ_i a[i + lag]·b[i], lag = 0 … 2m
        out: FloatArray = np.fft.irfft(fx[i] * fr[j], size)[n - 1 : n + 2 * m]
        return out

    cnt = np.round(corr(0, 0))
    with np.errstate(invalid="ignore", divide="ignore"):
        sr, sx = corr(0, 1) / cnt, corr(1, 0) / cnt
        var_r, var_x = corr(0, 2) / cnt - sr * sr, corr(2, 0) / cnt - sx * sx
        cov = corr(1, 1) / cnt - sr * sx
        rho = cov / np.sqrt(var_r * var_x)
    ok = (cnt >= 10) & (var_r > 0) & (var_x > 0)
    return np.where(ok, rho, np.nan)


def _tacho_speed(tacho: pd.DataFrame, metres: float) -> tuple[FloatArray, FloatArray]:
    """The tacho's t and speed [m/s] (centred difference of the count's distance)."""
    t = tacho["t"].to_numpy(dtype=float, na_value=np.nan)
    p = tacho["pulses"].to_numpy(dtype=float, na_value=np.nan)
    ok = np.isfinite(t) & np.isfinite(p)
    t, d = t[ok], p[ok] * metres
    order = np.argsort(t, kind="stable")
    t, d = t[order], d[order]
    keep = np.diff(t, prepend=-np.inf) > 0
    t, d = t[keep], d[keep]
    return t, np.gradient(d, t) if t.size > 1 else np.zeros(t.size)


def _sorted(frame: pd.DataFrame, cols: list[str]) -> dict[str, FloatArray]:
    """t and ``cols`` sorted by t (stable), rows with a NaN or repeated t left out; a stream
    already increasing (the usual case) is returned as its arrays, not copies of them."""
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    out = {"t": t, **{c: frame[c].to_numpy(dtype=float, na_value=np.nan) for c in cols}}
    if t.size and bool(np.isfinite(t[[0, -1]]).all()) and bool((t[1:] > t[:-1]).all()):  # increasing: all finite
        return out
    order = np.argsort(t, kind="stable")
    out = {k: v[order] for k, v in out.items()}
    keep = (np.diff(out["t"], prepend=-np.inf) > 0) & np.isfinite(out["t"])
    return {k: v[keep] for k, v in out.items()}


def _in_travel_frame(cab: pd.DataFrame | None, t: FloatArray, ax: FloatArray, rows: int = BLOCK_ROWS) -> FloatArray:
    """``ax`` turned to the travel frame: times the cab sign (+1 forward, −1 reverse) at each
    ``t``, ``rows`` samples at a time (the sign's lookup index and values for a block, not for
    a long run's whole 100 Hz stream; each product is the same)."""
    if cab is None or not len(cab):
        return ax.copy()
    te = cab["t"].to_numpy(dtype=float, na_value=np.nan)
    order = np.argsort(te, kind="stable")
    te, directions = te[order], cab["direction"].astype(str).to_numpy()[order]
    out = np.empty(t.size)
    for a in range(0, t.size, max(rows, 1)):
        out[a : a + rows] = ax[a : a + rows] * cab_signs(t[a : a + rows], te, directions)
    return out


def gps_speed(gps: pd.DataFrame) -> tuple[FloatArray, FloatArray]:
    """(t, speed) of the GPS: its ``speed_mps`` where logged, else |Δposition|/Δt of
    consecutive fixes (local plane), at the midpoint of each step of at most 2 s; only the
    D-GPS fixes when at least half the rows are D-GPS (a plain-GPS spell wanders by metres)."""
    if "speed_mps" in gps.columns and gps["speed_mps"].notna().sum() >= 10:
        s = _sorted(gps, ["speed_mps"])
        return s["t"], s["speed_mps"]
    fix = gps["fix"].to_numpy(dtype=float, na_value=np.nan) if "fix" in gps.columns else np.ones(len(gps))
    best = 2.0 if np.mean(fix >= 2) >= 0.5 else 1.0  # D-GPS where the receiver mostly has it
    s = _sorted(gps[fix >= best], ["lat", "lon"])
    lat, lon = np.radians(s["lat"]), np.radians(s["lon"])
    dt = np.diff(s["t"])
    dx = np.diff(lon) * np.cos(0.5 * (lat[1:] + lat[:-1])) * EARTH_R_M
    dy = np.diff(lat) * EARTH_R_M
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.hypot(dx, dy) / dt
    good = np.isfinite(v) & (dt <= 2.0)
    return (0.5 * (s["t"][1:] + s["t"][:-1]))[good], v[good]


def clock_offsets(
    streams: dict[str, pd.DataFrame | None],
    wheel_diameter_m: float | None,
    teeth: int | None,
    cfg: ClockConfig,
    cycle_s: float = 0.1,
) -> list[ClockOffset]:
    """The IMU's and the GPS' clock offsets against the tacho (module docstring); empty
    without a tacho, a plausible wheel, or with ``cfg.max_lag_s`` 0."""
    tacho = streams.get("tacho")
    if tacho is None or len(tacho) < 10 or not _plausible(wheel_diameter_m, teeth) or cfg.max_lag_s <= 0:
        return []
    assert wheel_diameter_m is not None and teeth is not None
    t_p, v_p = _tacho_speed(tacho, metres_per_pulse(wheel_diameter_m, teeth))
    moving = (v_p > MOVING_MPS).astype(float)
    out: list[ClockOffset] = []
    imu = streams.get("imu")
    if imu is not None and len(imu) >= 10 and "ax" in imu.columns:
        s = _sorted(imu, ["ax"])
        ax = _in_travel_frame(streams.get("cab"), s["t"], s["ax"])
        a_p = np.gradient(v_p, t_p) if t_p.size > 1 else v_p
        lag = estimate_lag(
            t_p, a_p, s["t"], ax, max_lag_s=cfg.max_lag_s, step_s=cycle_s, highpass_s=cfg.highpass_s, weight=moving
        )
        out += _offset("imu", lag, 0.0, cfg)
    gps = streams.get("gps")
    if gps is not None and len(gps) >= 10 and {"lat", "lon"} <= set(gps.columns):
        t_g, v_g = gps_speed(gps)
        lag = estimate_lag(
            t_p, v_p, t_g, v_g, max_lag_s=cfg.max_lag_s, step_s=cycle_s, highpass_s=cfg.highpass_s, weight=moving
        )
        out += _offset("gps", lag, 0.0, cfg)
    return out


def _plausible(wheel_diameter_m: float | None, teeth: int | None) -> bool:
    """A wheel the usability rule would accept for some vehicle (else that rule speaks)."""
    if wheel_diameter_m is None or teeth is None:
        return False
    lo, hi = ANY_WHEEL_DIAMETER_M
    return bool(np.isfinite(wheel_diameter_m) and lo <= wheel_diameter_m <= hi and TEETH[0] <= teeth <= TEETH[1])


def _offset(stream: str, lag: Lag | None, expected_s: float, cfg: ClockConfig) -> list[ClockOffset]:
    if lag is None:
        return []
    offset = lag.lag_s - expected_s
    determined = (
        lag.corr >= cfg.min_corr
        and lag.moving_s >= cfg.min_span_s
        and not lag.at_edge
        and lag.sigma_s <= SIGMA_SHARE * cfg.tolerance_s
    )
    return [
        ClockOffset(stream, offset, lag.sigma_s, lag.corr, determined, determined and abs(offset) > cfg.tolerance_s)
    ]


def _masked(name: str, frame: pd.DataFrame | None) -> pd.DataFrame | None:
    return None if frame is None else masked(name, frame)[0]


def clock_findings(run: Run, cfg: ClockConfig | None = None) -> list[Finding]:
    """``log.clock_offset`` warnings of ``logs check``: the offsets :func:`clock_offsets`
    finds beyond the tolerance (the pipeline corrects the same ones)."""
    cfg = cfg or ClockConfig()
    meta = run.meta
    if meta is None or not run.has("tacho"):
        return []
    # the streams as the pipeline reads them: samples outside the sensors' limits masked
    streams = {n: _masked(n, run.stream(n)) for n in ("tacho", "imu", "gps", "cab") if run.has(n)}
    offsets = clock_offsets(streams, meta.wheel_diameter_m, meta.teeth, cfg)
    return [
        Finding(
            "log.clock_offset",
            Severity.WARNING,
            o.stream,
            o.message,
            column="t",
            value=round(o.offset_s, 2),
            file=str(run.stream_file(o.stream) or run.folder),
        )
        for o in offsets
        if o.beyond_tolerance
    ]
