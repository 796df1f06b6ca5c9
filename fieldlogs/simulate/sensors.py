"""Sensor models: IMU, tachometer, D-GPS, radar — and the truth stream.

* **IMU** (ADIS16480 class, 100 Hz): true value + white noise + constant bias + Gauss-Markov
  drift, quantised to the output resolution. White noise is specified as the RMS of 100 ms
  averages, so one 10 ms sample has σ·√10. Gauss-Markov drift
  x[k+1] = φ·x[k] + √(1 − φ²)·σ·w, φ = exp(−Δt/τ), generated at 1 Hz (``lfilter``) and
  interpolated.
* **Tachometer** (10 Hz): cumulative pulses = floor(wheel revolutions × teeth), revolutions
  = wheel rolled distance / (π·D_true); the wheel rolls at |v|·(1 ± slip). Pulses never
  decrease whatever the direction. A two-phase tachometer (``tacho.two_phase``) also gives the
  sense of rotation per cycle, the ``direction`` column in the body frame: the sign of the
  displacement toward the F end over the cycle (k−1, k] where a pulse came, 0 where none did.
  Distance by pulses with the nominal diameter is rolled distance × D_nominal / D_true.
* **D-GPS** (1 Hz): true track position (DB GIS geometry) + Gauss-Markov error (σ, τ) +
  multipath bursts; outages (tunnels) fix 0 with empty lat/lon; fix 1 (no differential
  correction, larger error) for a while after an outage; nsat/hdop follow the conditions.
  Poor-sky stretches (``gps.poor_sky_*``) add white noise, frequent multipath bursts and
  spells of fix 1 (a two-state Markov chain per second with the configured share and mean
  spell length). A road-rail vehicle off rail stands ``road_offset_m`` beside the track at
  its on-rail km and drives onto / off the track over ``transfer_s`` (lateral offset
  L·(1 − cos πf)/2, f the remaining share of the transfer: no jump the trust filter would see).
* **Radar** (~3 Hz): |v| + N(0, max(pct·v, min)); unaffected by slip; 0 below the cut-off.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy.signal import lfilter

from dbtools.masks import true_runs
from fieldlogs.simulate.running import DT, Motion
from fieldlogs.simulate.scenario import Scenario
from fieldlogs.simulate.track import TrackGeometry
from schemas.units import KMH_PER_S, wheel_circumference_m

FloatArray = npt.NDArray[np.float64]
TACHO_STEP = 10
"""Simulation steps per tacho / truth sample (10 Hz)."""
GPS_STEP = 100


def gauss_markov(rng: np.random.Generator, n: int, step_s: float, sigma: float, tau_s: float) -> FloatArray:
    """Stationary first-order Gauss-Markov sequence (n samples, step_s apart)."""
    if sigma <= 0 or n == 0:
        return np.zeros(n)
    phi = float(np.exp(-step_s / tau_s))
    w = rng.standard_normal(n) * sigma * np.sqrt(1 - phi * phi)
    w[0] = rng.standard_normal() * sigma
    return np.asarray(lfilter([1.0], [1.0, -phi], w))


def _slow(rng: np.random.Generator, t: FloatArray, sigma: float, tau_s: float) -> FloatArray:
    """Gauss-Markov drift at 1 Hz, linearly interpolated to ``t``."""
    if sigma <= 0:
        return np.zeros_like(t)
    n = int(np.ceil(t[-1])) + 2 if len(t) else 1
    x = gauss_markov(rng, n, 1.0, sigma, tau_s)
    return np.interp(t, np.arange(n, dtype=float), x)


def _quantise(x: FloatArray, lsb: float) -> FloatArray:
    return np.round(x / lsb) * lsb if lsb > 0 else x


def imu_stream(
    true: dict[str, FloatArray], motion: Motion, scenario: Scenario, rng: np.random.Generator
) -> pd.DataFrame:
    cfg = scenario.imu
    acc_lsb = cfg.accel_lsb_mps2
    gyro_lsb = np.radians(cfg.gyro_lsb_deg_s)
    out: dict[str, FloatArray] = {"t": motion.t}
    sqrt10 = np.sqrt(0.1 / DT)
    for axis in ("ax", "ay", "az", "wx", "wy", "wz"):
        x = true[axis].copy()
        if scenario.noise:
            if axis[0] == "a":
                unit = KMH_PER_S
                white, bias, drift = cfg.accel_white_kmh_s, cfg.accel_bias_kmh_s, cfg.accel_drift_kmh_s
            else:
                unit = np.radians(1.0)
                white, bias, drift = cfg.gyro_white_deg_s, cfg.gyro_bias_deg_s, cfg.gyro_drift_deg_s
            x += unit * (
                rng.standard_normal(motion.n) * white * sqrt10
                + rng.standard_normal() * bias
                + _slow(rng, motion.t, drift, cfg.drift_tau_s)
            )
        out[axis] = _quantise(x, acc_lsb if axis[0] == "a" else gyro_lsb)
    return pd.DataFrame(out)


def wheel_draw(scenario: Scenario, rng: np.random.Generator) -> tuple[float, float]:
    """(true diameter [m], wear [%]) of a tacho wheel: the nominal diameter worn by a draw of
    ``tacho.wear_pct``."""
    lo, hi = scenario.tacho.wear_pct
    wear = float(rng.uniform(lo, hi)) if hi > lo else lo
    return scenario.tacho.wheel_diameter_m * (1.0 - wear / 100.0), wear


def wheel_distance(motion: Motion, factor: FloatArray) -> FloatArray:
    """Distance rolled by the wheel circumference [m], cumulative at every step."""
    vw = motion.v * factor
    c = np.cumsum(vw)
    return np.asarray(DT * (c - 0.5 * (vw[0] + vw)), dtype=float)


def tacho_stream(
    rolled: FloatArray, motion: Motion, d_true: float, teeth: int, two_phase: bool = False, sense: int = 1
) -> pd.DataFrame:
    """The pulses of a wheel that rolled ``rolled``; ``sense`` = −1: the ``direction`` of the R
    cab's tacho, in its own frame (+1 toward the vehicle's R end)."""
    k = np.arange(0, motion.n, TACHO_STEP)
    revs = rolled[k] / wheel_circumference_m(d_true)
    pulses = np.maximum.accumulate(np.floor(revs * teeth + 1e-9).astype(np.int64))
    frame = pd.DataFrame({"t": motion.t[k], "pulses": pulses})
    if two_phase:
        toward_f = np.cumsum(sense * motion.speed_toward_f)[k]  # ∝ displacement toward the cab's forward end
        moved = np.diff(toward_f, prepend=0.0)
        came = np.diff(pulses, prepend=pulses[:1]) > 0
        frame["direction"] = np.where(came, np.sign(moved), 0).astype(np.int64)
    return frame


def truth_stream(motion: Motion, slipping: npt.NDArray[np.bool_], line_code: str, track: str) -> pd.DataFrame:
    k = np.arange(0, motion.n, TACHO_STEP)
    on = motion.on_rail[k]
    return pd.DataFrame(
        {
            "t": motion.t[k],
            "line_code": pd.Series(line_code, index=range(len(k)), dtype="string").where(on),
            "track": pd.Series(track, index=range(len(k)), dtype="string").where(on),
            "km_m": np.where(on, np.round(motion.km[k], 4), np.nan),
            "speed_mps": np.round(motion.speed_toward_f[k], 5) + 0.0,
            "slipping": slipping[k].astype(np.int64),
        }
    )


def radar_stream(motion: Motion, scenario: Scenario, rng: np.random.Generator) -> pd.DataFrame:
    cfg = scenario.radar
    t = np.arange(0.0, motion.duration_s + 1e-9, 1.0 / cfg.rate_hz)
    v = np.interp(t, motion.t, motion.v)
    if scenario.noise:
        sigma = np.maximum(cfg.noise_pct / 100.0 * v, cfg.noise_min_mps)
        v = v + rng.standard_normal(len(t)) * sigma
    v = np.where(v < cfg.cutoff_mps, 0.0, v)
    return pd.DataFrame({"t": np.round(t, 3), "speed_mps": np.round(v, 4)})


def _bursts(rng: np.random.Generator, t: FloatArray, scenario: Scenario) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Multipath error (east, north) [m] and a 0..1 burst intensity at the GPS times."""
    cfg = scenario.gps
    ex, ey, level = np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)
    if not scenario.noise or cfg.multipath_per_hour <= 0 or len(t) < 2:
        return ex, ey, level
    n = int(rng.poisson(cfg.multipath_per_hour * t[-1] / 3600.0))
    for _ in range(n):
        t0 = float(rng.uniform(0.0, t[-1]))
        dur = float(rng.uniform(*cfg.multipath_s))
        mag = float(rng.uniform(*cfg.multipath_m))
        ang = float(rng.uniform(0.0, 2 * np.pi))
        inside = (t >= t0) & (t <= t0 + dur)
        shape = np.where(inside, np.sin(np.pi * np.clip((t - t0) / dur, 0.0, 1.0)) ** 0.5, 0.0)
        ex += mag * np.cos(ang) * shape
        ey += mag * np.sin(ang) * shape
        level = np.maximum(level, shape)
    return ex, ey, level


def road_lateral(motion: Motion, scenario: Scenario, t: FloatArray) -> FloatArray:
    """Lateral offset of the GPS antenna from the track at times ``t`` [m] (+ left of
    increasing km): 0 on rail; a road-rail vehicle off rail stands ``road_offset_m`` beside
    the track and drives over ``transfer_s`` between there and the track."""
    rr = scenario.road_rail
    on = np.interp(t, motion.t, motion.on_rail.astype(float)) >= 0.5
    if not scenario.is_road_rail or not motion.on_rail.any():
        return np.where(on, 0.0, rr.road_offset_m)
    k_on = np.flatnonzero(motion.on_rail)
    t_on, t_off = float(motion.t[k_on[0]]), float(motion.t[k_on[-1]]) + DT
    away = np.where(t < t_on - 1e-9, t_on - t, np.where(t >= t_off - 1e-9, t - t_off + DT, 0.0))
    if rr.transfer_s <= 0:
        frac = (away > 0).astype(float)
    else:
        f = np.clip(away / rr.transfer_s, 0.0, 1.0)
        frac = 0.5 * (1.0 - np.cos(np.pi * f))
    return rr.road_offset_m * frac


def in_spans(km: FloatArray, spans: tuple[tuple[float, float], ...]) -> npt.NDArray[np.bool_]:
    """True where ``km`` lies in one of the [from, to] spans."""
    out = np.zeros(km.shape, dtype=bool)
    for a, b in spans:
        out |= (km >= a) & (km <= b)
    return out


def _poor_sky(
    rng: np.random.Generator, t: FloatArray, inside: npt.NDArray[np.bool_], scenario: Scenario
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.bool_], FloatArray]:
    """Extra error (east, north) [m], the fix-1 spells and the burst intensity in poor sky."""
    cfg = scenario.gps
    n = len(t)
    ex = np.where(inside, rng.standard_normal(n) * cfg.poor_sky_white_m, 0.0)
    ey = np.where(inside, rng.standard_normal(n) * cfg.poor_sky_white_m, 0.0)
    # fix-1 spells: two-state Markov chain per fix, mean spell length L, stationary share p
    p_exit = 1.0 / cfg.poor_sky_fix1_spell_s
    p_enter = cfg.poor_sky_fix1_share / (1.0 - cfg.poor_sky_fix1_share) * p_exit
    u = rng.random(n)
    spell = np.zeros(n, dtype=bool)
    state = False
    for i in range(n):
        state = bool(inside[i]) and (u[i] >= p_exit if state else u[i] < p_enter)
        spell[i] = state
    fx = gauss_markov(rng, n, 1.0, cfg.fix1_sigma_m, 30.0)
    fy = gauss_markov(rng, n, 1.0, cfg.fix1_sigma_m, 30.0)
    ex += np.where(spell, fx, 0.0)
    ey += np.where(spell, fy, 0.0)
    # multipath: bursts placed uniformly over the time spent in poor sky
    level = np.zeros(n)
    idx = np.flatnonzero(inside)
    m = int(rng.poisson(cfg.poor_sky_multipath_per_hour * idx.size / 3600.0)) if idx.size else 0
    for _ in range(m):
        t0 = float(t[idx[int(rng.integers(idx.size))]])
        dur = float(rng.uniform(*cfg.multipath_s))
        mag = float(rng.uniform(*cfg.multipath_m))
        ang = float(rng.uniform(0.0, 2 * np.pi))
        shape = np.where((t >= t0) & (t <= t0 + dur), np.sin(np.pi * np.clip((t - t0) / dur, 0.0, 1.0)) ** 0.5, 0.0)
        ex += mag * np.cos(ang) * shape
        ey += mag * np.sin(ang) * shape
        level = np.maximum(level, shape)
    return ex, ey, spell, level


def gps_stream(
    motion: Motion, geom: TrackGeometry, scenario: Scenario, rng: np.random.Generator
) -> tuple[pd.DataFrame, list[tuple[float, float]]]:
    """The GPS frame and the (t0, t1) of every outage."""
    cfg = scenario.gps
    k = np.arange(0, motion.n, GPS_STEP)
    t = motion.t[k]
    km = motion.km[k]
    on = motion.on_rail[k]
    lateral = road_lateral(motion, scenario, t)
    x, y = geom.xy(km, lateral)
    outage = np.zeros(len(k), dtype=bool)
    for a, b in cfg.outages_km_m:
        outage |= on & (km >= a) & (km <= b)
    last_out = np.maximum.accumulate(np.where(outage, t, -np.inf))
    fix1 = ~outage & (t - last_out <= cfg.reacquire_s)
    fix = np.where(outage, 0, np.where(fix1, 1, 2)).astype(np.int64)
    nsat = np.full(len(k), float(cfg.nsat))
    if scenario.noise:
        x = x + gauss_markov(rng, len(k), 1.0, cfg.sigma_m, cfg.tau_s)
        y = y + gauss_markov(rng, len(k), 1.0, cfg.sigma_m, cfg.tau_s)
        x = x + fix1 * gauss_markov(rng, len(k), 1.0, cfg.fix1_sigma_m, 30.0)
        y = y + fix1 * gauss_markov(rng, len(k), 1.0, cfg.fix1_sigma_m, 30.0)
        mx, my, level = _bursts(rng, t, scenario)
        x, y = x + mx, y + my
        nsat = nsat + gauss_markov(rng, len(k), 1.0, 1.0, 120.0) - 3.0 * level
        poor = in_spans(km, cfg.poor_sky_km_m) & ~outage
        if poor.any():
            px, py, spell, plevel = _poor_sky(rng, t, poor, scenario)
            x, y = x + px, y + py
            fix = np.where(spell & (fix == 2), 1, fix)
            nsat = np.where(poor, np.minimum(nsat, cfg.poor_sky_nsat), nsat) - 3.0 * plevel
            level = np.maximum(level, plevel)
    else:
        level = np.zeros(len(k))
    nsat = np.where(fix1, np.minimum(nsat, 6.0), nsat)
    nsat = np.clip(np.round(nsat), 4, 64).astype(np.int64)
    nsat[outage] = rng.integers(0, 4, int(outage.sum())) if scenario.noise else 0
    hdop = np.round(cfg.hdop * np.sqrt(cfg.nsat / np.maximum(nsat, 1)) * (1.0 + 2.0 * level), 1)
    hdop = np.clip(hdop, 0.5, 99.9)
    hdop[outage] = np.nan
    lon, lat = geom.lonlat(x, y)
    lat = np.where(outage, np.nan, np.round(lat, 9))
    lon = np.where(outage, np.nan, np.round(lon, 9))
    frame = pd.DataFrame({"t": t, "lat": lat, "lon": lon, "fix": fix, "nsat": nsat, "hdop": hdop})
    starts, ends = true_runs(outage)
    spans = [(float(t[s]), float(t[e - 1])) for s, e in zip(starts, ends, strict=True)]
    return frame, spans
