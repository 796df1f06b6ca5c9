"""Slip/slide detection and inertial correction of the pulse odometry [S000 §3.1, SPEC §5.1].

Everything runs on the 100 ms cycle arrays of :class:`Cycles`. Detection, jerks, smoothing
and the start-point search are vectorised over the whole run; only the (rare) episodes are
visited in a Python loop, each integrated with ``np.cumsum`` over at most 10 s of cycles.

Travel frame
    Pulses are unsigned, the IMU is body-fixed. With ``cab`` = +1 the travel direction is
    body +x, with −1 it is −x: the travel frame is the body frame turned 180° about z, so
    ``ax, ay, wx, wy`` change sign and ``az, wz`` do not. All formulas below are in the
    travel frame (x along travel, y left, z up; SPEC §4.1), pitch θ is nose-up in the travel
    direction (the gradient climbed), roll ψ is positive with the left side up.

Streams and alignment
    Pulse speed ``v`` is the per-cycle backward difference; A_p = dv/dt. The pulse stream is
    delayed ``pulse_delay_cycles`` (300 ms) to line up with the IMU, so index k of the
    *aligned* arrays holds pulse and IMU data of the same physical instant. A_p and a_x are
    smoothed with the trailing 3 s moving average ``MA3``. Before differentiating, the pulse
    speed is averaged over ``SPEED_AVG_S`` (1 s) and a_x gets the identical 1 s average, so
    both go through the same filter K = MA3∘MA1 (a 3.9 s trapezoid) and, while adhering,
    ``K·a_x − K·A_p = K·(G·sinθ)`` exactly, whatever the jerk. Why the extra 1 s: at 10 Hz one
    pulse (≈ 3 cm) is 0.3 m/s of speed and 3 m/s² of A_p; ``MA3`` alone leaves ±0.11 m/s²
    (0.4 km/h/s, a third of Ta, false alarms on 25 ‰ lines) and steps Jp by 0.36 km/h/s per
    0.1 s, above its 0.15 limit, so the start-point condition would almost never hold. After
    ``MA1`` the residue is ±0.025 m/s² and Jp steps by 0.036 km/h/s. Cost: ≈ 0.3 s more
    detection latency (0.7–0.8 s from onset for a 3.5–4.5 m/s wheel-speed step, 0.3 s of
    it the pulse delay); the look-back absorbs it.

Detection (eq. 1)
    ``|a_x − A_p| > Ta`` on the smoothed aligned values, pulse speed ≥ ``min_speed_kmh``.
    ``a_x − A_p < −Ta``: the wheel accelerates faster than the body → *slip* (traction);
    ``> +Ta``: the wheel decelerates faster → *slide* (braking). The gravity term G·sinθ is
    at most Ta (35 ‰), so the sign decides. Only rising edges of the mask open an episode.

Correction start point
    From the detection cycle minus ``lookback_s`` search backwards (at most
    ``SEARCH_SPAN_S``, never before the previous episode's end) for the last cycle at which
    |Ji| ≤ 0.1, |Jp| ≤ 0.15 and |Ji − Jp| < 0.05 km/h/s per 0.1 s held for ``hold_cycles``
    consecutive cycles (Ji, Jp: per-cycle differences of smoothed a_x, A_p). Vectorised as
    "last index ≤ k where the rolling condition holds" (``np.maximum.accumulate``). If none
    is found the look-back point itself is used (``detail['start_found'] = False``).

Attitude at the start point (i0)
    Pitch (eq. 3): θ̄ = arcsin((a_x0 − A_p0)/G) with A_p0 the least-squares acceleration of a
    quadratic fitted to the M = 3.9 s of pulse distances ending at i0 and a_x0 the *same*
    linear functional applied to the a_x cycle means (``_lsq_accel_weights``), so
    a_x0 − A_p0 is a weighted mean of G·sinθ for any speed profile, with ≈ 0.003 m/s² of
    pulse-quantisation error instead of ±0.025 (a two-speed difference). Roll (eq. 11):
    ψ̄ = arctan(K·(a_y − v·ω_z) / K·a_z) (in a canted left curve a_y = v²/R + G·sinψ, ψ < 0).
    Both are means over a window centred ≈ 1.9 s before i0; they are carried to i0 with the
    gyros, ``x(i0) = x̄ + Σ_l ẋ(i0−l)·dt·S_{l+1}`` with ``S_l`` the tail sums of the window
    weights (exact for any rate history), so a vertical curve or a transition just before
    the start point does not bias θ0, ψ0. |θ̄| is limited to arcsin(Ta/G) (35 ‰): more
    means the start point was not adhering (``detail['theta_clipped']``). The start speed
    v0 is the 1 s mean pulse speed carried to i0 the same way with A_x; the pulse distance
    at i0 anchors the distance.

Attitude propagation (eqs. 4, 6, 12 in our frame)
    Kinematics of SPEC §4.1 (heading Ψ, nose-up pitch θ, roll ψ):
    ``wx = ψ̇ + Ψ̇·sinθ``, ``wy = −θ̇·cosψ + Ψ̇·cosθ·sinψ``, ``wz = θ̇·sinψ + Ψ̇·cosθ·cosψ``.
    Eliminating Ψ̇ (wz·sinψ − wy·cosψ):

        θ̇ = −wy·cosψ + wz·sinψ                                (eq. 12, our frame)

    i.e. the papers' ω_y'' = ω_y + ω_z·sinψ with ω_y = −wy and cosψ ≈ 1 (eq. 5 and the first
    two terms of eq. 12); θ(t) = θ0 + ∫θ̇ dt (eq. 4). The papers' third term −k·ω_x·sinψ
    (k = ±1 by curve hand) has no counterpart in rigid-body kinematics: with k = sign(ω_z)
    it integrates to k·(cosψ − cosψ0), an empirical correction for their installation, and
    it is left out (it would bias exact data by up to 1 − cos ψ ≈ 0.005 rad at 100 mm cant).
    Roll: ψ(t) = ψ0 + ∫ωx dt (eq. 6); a second pass adds the exact −Ψ̇·sinθ term with
    Ψ̇·cosθ = wy·sinψ + wz·cosψ (on 25 ‰ in an R 400 m curve at 20 m/s eq. 6 alone drifts
    0.05 rad/s·0.025·10 s ≈ 0.013 rad in ψ).

Correction (eq. 2)
    A_x = a_x − G·sinθ (θ at mid-cycle), integrated from i0 (trapezoid of the cycle means,
    which is exact for the cycle-mean speed under a linear acceleration) to the speed, then
    to the distance. Negative speeds are clipped (the distance never decreases).

Re-adhesion
    After detection, the first cycle with ``|a_x − A_p| ≤ Ta`` and
    ``|v_inertial − v_pulse| ≤ β·(t − t0)``. From there the distance continues on the pulses
    with a constant offset (continuous, never decreasing). A correction still running
    ``max_correction_s`` after i0 ends there as a *fail-safe* episode (``failsafe=True``):
    the distance continues on the pulses and the solver makes the position uncertain.
    Only rising edges of the detection mask open an episode, and a new start point needs
    the look-back's room after the previous end (see ``find_episodes``): otherwise a
    re-adhesion is re-opened (it was premature — with a 3.9 s filter this is the rule for
    slips of about the window's length) and a detection just after a fail-safe is ignored.
    With the SPEC parameters a correction lasts ≈ look-back 2.3 s + slip + filter tail
    ≈ 3.5 s, so slips longer than ≈ 4 s end as fail-safe.

Output time base
    Episodes are found on the aligned arrays and written back shifted by the pulse delay,
    so ``d``, ``v`` and the episode indices refer to the cycle grid of ``cycles.t`` (the
    correction is retroactive from the start point, as the onboard unit recomputes it once
    it detects the slip at ``t_detect``, which is the clock time of the detection cycle).

Allowance (eq. 13)
    ``allowance[k]`` = Σ over finished episodes of ½·Δa·T² (T = their correction time)
    plus, inside a running episode, ½·Δa·(t − t_start)². It is continuous, never decreases,
    and equals the full eq. 13 budget from each episode's end on (22.8 m for T = 10 s).

NaN policy: missing IMU cycles are bridged by linear interpolation for the integration; the
moving averages use what exists; no detection where a smoothed value is missing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import Cycles, delay, moving_average
from fieldlogs.pipeline.types import FloatArray, Odometry, SlipEpisode, pulse_only_odometry, slip_budget_m
from schemas.units import G, kmh_s_to_mps2, mps2_to_kmh_s

#: Averaging of the pulse speed (and of a_x, identically) before the 3 s moving average [s].
SPEED_AVG_S = 1.0
#: How far before the look-back point the start-point search may go [s].
SEARCH_SPAN_S = 3.0
CYCLE_S = 0.1
#: Error budget of a radar-bridged episode: this share of its distance plus a constant [%, m].
RADAR_ERROR_PCT = 1.0
RADAR_ERROR_M = 0.5


def correct_odometry(cycles: Cycles, cfg: OdometryConfig, radar_mps: FloatArray | None = None) -> Odometry:
    """Pulse odometry with slip/slide episodes replaced by the inertial solution (SPEC §5.1).

    ``radar_mps``: an independent ground speed on the cycle grid (2-frequency CW radar
    [S004]; NaN where there is none). Detection is unchanged, but over an episode the
    radar covers completely its speed replaces the inertial one: it does not drift, so the
    episode's error budget is the radar's (1 % of the distance + 0.5 m) when smaller than
    eq. 13's.
    """
    n = cycles.n
    d_pulse = np.nan_to_num(np.asarray(cycles.d_pulse, dtype=float), nan=0.0)
    v_pulse = np.nan_to_num(np.asarray(cycles.v_pulse, dtype=float), nan=0.0)
    if not cycles.has_imu or not cycles.has_tacho or n < 3:
        return pulse_only_odometry(d_pulse, v_pulse)
    s = _Streams(cycles, cfg, d_pulse, v_pulse)
    episodes = s.find_episodes()
    return s.assemble(episodes, radar_mps)


@dataclass
class _Integration:
    i_lim: int
    v_in: FloatArray
    theta: FloatArray
    theta0: float
    psi0: float
    v0: float
    clipped: bool


class _Streams:
    """The aligned, smoothed streams of one run and the per-episode integration."""

    def __init__(self, cycles: Cycles, cfg: OdometryConfig, d_pulse: FloatArray, v_pulse: FloatArray) -> None:
        self.cfg = cfg
        self.n = n = cycles.n
        self.t = np.asarray(cycles.t, dtype=float)
        dt = np.asarray(cycles.dt, dtype=float)
        self.cyc = float(np.median(dt)) if n > 1 else CYCLE_S
        self.dt = np.where(np.isfinite(dt) & (dt > 0), dt, self.cyc)
        self.uniform = bool(np.all(np.abs(self.dt - self.cyc) < 1e-6))
        self.D = D = max(int(cfg.pulse_delay_cycles), 0)
        self.W = max(round(cfg.avg_window_s / self.cyc), 1)
        self.P = max(round(SPEED_AVG_S / self.cyc), 1)
        self.d_pulse, self.v_pulse = d_pulse, v_pulse
        self._cache: dict[int, _Integration] = {}
        # filter K = MA_W ∘ MA_P as weights on lags 0..M−1, and its tail sums S_l = Σ_{m≥l} w_m
        self.kernel = np.convolve(np.full(self.P, 1.0 / self.P), np.full(self.W, 1.0 / self.W))
        self.M = self.kernel.size
        self.tail = _tail(self.kernel)
        self.tail_p = _tail(np.full(self.P, 1.0 / self.P))
        self.lsq_c, self.lsq_g = _lsq_accel_weights(self.M, self.cyc)
        self.tail_g = _tail(self.lsq_g[::-1])

        # travel frame (cab −1: body turned 180° about z); IMU gaps are bridged per window
        cab = np.asarray(cycles.cab)
        self.sign = None if (cab >= 0).all() else np.where(cab < 0, -1.0, 1.0)
        self.imu = {c: np.asarray(cycles.imu[c], dtype=float) for c in ("ax", "ay", "az", "wx", "wy", "wz")}
        ax_raw = self.imu["ax"] if self.sign is None else self.imu["ax"] * self.sign

        # pulse stream delayed onto the IMU (aligned index k ↔ output index k − D); the first
        # pulse speed is 0 by construction and the delay repeats it: everything before
        # ``warm`` is excluded from detection and from the start-point windows
        self.vp = delay(v_pulse, D)
        self.dp = delay(d_pulse, D)
        self.vp1 = _ma(self.vp, self.P)
        ap = np.diff(self.vp1, prepend=self.vp1[0])
        ap /= self.dt
        self.aps = _ma(ap, self.W)
        self.axs = _ma(_ma(ax_raw, self.P), self.W)
        self.diff = self.axs - self.aps
        self.ta = cfg.ta_mps2
        self.warm = warm = min(D + self.P + self.M, n)  # first cycle whose windows hold only valid data

        # detection mask (eq. 1) and its rising edges
        with np.errstate(invalid="ignore"):
            mask = (np.abs(self.diff) > self.ta) & (self.vp1 >= cfg.min_speed_kmh / 3.6)
        mask[:warm] = False
        self.mask = mask
        self.onsets = np.flatnonzero(mask[1:] & ~mask[:-1]) + 1

        # start-point condition: jerks per 0.1 s, held for hold_cycles → last index where it held
        per: float | FloatArray = 0.1 / self.cyc if self.uniform else 0.1 / self.dt
        ji = np.diff(self.axs, prepend=np.nan) * per
        jp = np.diff(self.aps, prepend=np.nan) * per
        with np.errstate(invalid="ignore"):
            ok = np.abs(ji) <= kmh_s_to_mps2(cfg.jerk_imu_max_kmh_s) + 1e-12
            ok &= np.abs(jp) <= kmh_s_to_mps2(cfg.jerk_pulse_max_kmh_s) + 1e-12
            ji -= jp
            ok &= np.abs(ji) < kmh_s_to_mps2(cfg.jerk_diff_max_kmh_s)
        ok[:warm] = False
        h = max(int(cfg.hold_cycles), 1)
        run = ok.copy()
        for lag in range(1, h):
            run[lag:] &= ok[:-lag]
            run[:lag] = False
        self.last_hold = np.maximum.accumulate(np.where(run, np.arange(n), -1))

    def imu_window(self, name: str, sl: slice, fill: float = 0.0) -> FloatArray:
        """Travel-frame IMU column over a window, gaps bridged linearly (edges held)."""
        x = self.imu[name][sl]
        if self.sign is not None and name in ("ax", "ay", "wx", "wy"):
            x = x * self.sign[sl]
        return _bridge(x, fill)

    # ------------------------------------------------------------------ episodes
    def find_episodes(self) -> list[tuple[SlipEpisode, FloatArray]]:
        """Episodes in time order, each with its inertial speed on the aligned cycles i0..ie.

        A start point needs ``lookback`` cycles of room after the previous episode's end ie
        (and after a fail-safe also a full filter window, so that θ0 and v0 are computed
        from data of after the disturbance). A detection without that room is
        * after a re-adhesion: proof that the re-adhesion was premature (typically the
          slip's onset has left the 3 s window before its end has entered it) — the
          previous correction is re-opened and continues from its own start point;
        * after a fail-safe: still the same disturbance — ignored, the distance stays on
          the pulses (the position is uncertain anyway); listed in ``redetect_t``.
        """
        cfg = self.cfg
        episodes: list[tuple[SlipEpisode, FloatArray]] = []
        lookback = round(cfg.lookback_s / self.cyc)
        span = round(SEARCH_SPAN_S / self.cyc)
        floor = self.warm
        pos = 0
        while True:
            j = int(np.searchsorted(self.onsets, pos))
            if j >= self.onsets.size:
                break
            det = int(self.onsets[j])
            prev = episodes[-1][0] if episodes else None
            if prev is not None and det - lookback < floor:
                pd = prev.detail
                pd["redetect_t"].append(float(self.t[det]))
                if prev.failsafe:
                    pos = det + 1
                    continue
                episodes.pop()
                ep, v_in = self._episode(
                    pd["i_detect_aligned"], pd["i_start_aligned"], pd["start_found"], det, pd["redetect_t"]
                )
            else:
                i0, found = self._start_point(det, lookback, span, floor)
                ep, v_in = self._episode(det, i0, found, det, [])
            episodes.append((ep, v_in))
            ie = ep.detail["i_end_aligned"]
            floor = ie + self.M if ep.failsafe else ie + 1
            pos = ie + 1
        return episodes

    def _start_point(self, det: int, lookback: int, span: int, floor: int) -> tuple[int, bool]:
        k = det - lookback
        lo = max(floor, det - lookback - span)
        if k < lo:
            return max(min(det - 1, floor), 0), False
        j = int(self.last_hold[k])
        if j >= lo:
            return j, True
        return k, False

    def _window(self, i0: int) -> slice:
        """Cycles of the filter window ending at i0."""
        return slice(max(i0 - self.M + 1, 0), i0 + 1)

    def _kmean(self, x: FloatArray) -> float:
        """Filter-weighted mean of a window slice (oldest first), NaNs skipped."""
        seg = x[::-1]
        w = self.kernel[: seg.size]
        ok = np.isfinite(seg)
        sw = float(w[ok].sum())
        return float(np.dot(w[ok], seg[ok]) / sw) if sw > 0 else float("nan")

    def _carry(self, rate: FloatArray, h: FloatArray, tail: FloatArray) -> float:
        """Σ_l rate(i0−l)·dt·S_{l+1} over a window slice (oldest first) ending at i0: moves a
        filter-window mean to the window's last cycle."""
        m = min(rate.size, tail.size - 1)
        seg = (rate * h)[::-1][:m]
        return float(np.dot(seg, tail[1 : m + 1]))

    def _integrate(self, i0: int) -> _Integration:
        """Attitude at start point i0 and the inertial solution for up to max_correction_s
        (cached: a re-opened episode keeps its start point)."""
        if i0 in self._cache:
            return self._cache[i0]
        cfg = self.cfg
        n, t, dt = self.n, self.t, self.dt
        t_lim = t[i0] + cfg.max_correction_s
        i_lim = min(int(np.searchsorted(t, t_lim - 1e-9)), n - 1)
        w = self._window(i0)  # filter window ending at i0
        span = slice(w.start, i_lim + 1)  # window + integration, IMU bridged once
        ax, ay, az = self.imu_window("ax", span), self.imu_window("ay", span), self.imu_window("az", span, G)
        wx, wy, wz = self.imu_window("wx", span), self.imu_window("wy", span), self.imu_window("wz", span)
        nw = i0 - w.start + 1
        pre, post = slice(0, nw), slice(nw - 1, None)

        # attitude and speed at the start point (eqs. 3, 11), carried from window mean to i0
        hw = dt[w]
        psi_bar = float(np.arctan2(self._kmean(ay[pre] - self.vp[w] * wz[pre]), self._kmean(az[pre])))
        psi0 = psi_bar + self._carry(wx[pre], hw, self.tail)
        if nw == self.M:  # least-squares A_p0 (see _lsq_accel_weights)
            diff0 = float(np.dot(self.lsq_g, ax[pre]) - np.dot(self.lsq_c, self.dp[w]))
            tail_th = self.tail_g
        else:
            diff0 = float(self.diff[i0]) if np.isfinite(self.diff[i0]) else 0.0
            tail_th = self.tail
        # |G·sinθ| ≤ Ta by design (35 ‰); more means the start point was not adhering
        theta_max = float(np.arcsin(min(self.ta / G, 1.0)))
        theta_bar = float(np.arcsin(np.clip(diff0 / G, -1.0, 1.0)))
        clipped = abs(theta_bar) > theta_max
        theta_bar = float(np.clip(theta_bar, -theta_max, theta_max))
        theta0 = theta_bar + self._carry(-wy[pre] * np.cos(psi0) + wz[pre] * np.sin(psi0), hw, tail_th)
        v0 = float(self.vp1[i0]) + self._carry(ax[pre] - G * np.sin(theta0), hw, self.tail_p)

        # integrate over at most max_correction_s (eqs. 4, 6, 12, 2)
        sl = slice(i0, i_lim + 1)
        h = dt[sl].copy()
        h[0] = 0.0
        ax, wx, wy, wz = ax[post], wx[post], wy[post], wz[post]
        psi = psi0 + np.cumsum(wx * h)
        theta_dot = -wy * np.cos(psi) + wz * np.sin(psi)
        theta = theta0 + np.cumsum(theta_dot * h)
        yaw_c = wy * np.sin(psi) + wz * np.cos(psi)  # Ψ̇·cosθ
        psi = psi0 + np.cumsum((wx - yaw_c * np.tan(theta)) * h)
        theta_dot = -wy * np.cos(psi) + wz * np.sin(psi)
        theta = theta0 + np.cumsum(theta_dot * h)
        theta_mid = theta - 0.5 * theta_dot * h
        acc = ax - G * np.sin(theta_mid)
        dv = np.concatenate([[0.0], 0.5 * (acc[1:] + acc[:-1]) * h[1:]])
        v_in = np.maximum(v0 + np.cumsum(dv), 0.0)
        res = _Integration(i_lim, v_in, theta, theta0, psi0, v0, clipped)
        self._cache[i0] = res
        return res

    def _episode(
        self, det: int, i0: int, found: bool, after: int, redetect_t: list[float]
    ) -> tuple[SlipEpisode, FloatArray]:
        """Episode detected at ``det`` corrected from start point i0; re-adhesion is looked
        for after cycle ``after`` (later than ``det`` when a premature one was re-opened)."""
        cfg = self.cfg
        n, t = self.n, self.t
        ig = self._integrate(i0)
        i_lim, v_in, theta = ig.i_lim, ig.v_in, ig.theta
        sl = slice(i0, i_lim + 1)

        # re-adhesion after detection, else fail-safe at the time limit, else end of data
        tt = t[sl] - t[i0]
        with np.errstate(invalid="ignore"):
            cond = (np.abs(self.diff[sl]) <= self.ta) & (np.abs(v_in - self.vp[sl]) <= cfg.beta_mps2 * tt)
        cond[: max(after - i0 + 1, 0)] = False
        hit = np.flatnonzero(cond)
        readhered = hit.size > 0
        failsafe = False
        if readhered:
            ie = i0 + int(hit[0])
        elif t[i_lim] - t[i0] >= cfg.max_correction_s - 1e-9:
            ie, failsafe = i_lim, True
        else:
            ie = n - 1
        m_end = ie - i0 + 1
        v_in, theta = v_in[:m_end], theta[:m_end]
        duration = float(t[ie] - t[i0])
        kind = "slip" if float(self.diff[det]) < 0 else "slide"
        detail: dict[str, Any] = {
            "theta0_rad": ig.theta0,
            "psi0_rad": ig.psi0,
            "theta_end_rad": float(theta[-1]),
            "v0_mps": ig.v0,
            "diff_at_detect_kmh_s": mps2_to_kmh_s(float(self.diff[det])),
            "ax_at_detect_kmh_s": mps2_to_kmh_s(float(self.axs[det])),
            "ap_at_detect_kmh_s": mps2_to_kmh_s(float(self.aps[det])),
            "v_pulse_at_detect_mps": float(self.vp1[det]),
            "start_found": found,
            "theta_clipped": ig.clipped,
            "lookback_s": float(t[det] - t[i0]),
            "delay_cycles": self.D,
            "i_detect_aligned": det,
            "i_start_aligned": i0,
            "i_end_aligned": ie,
            "truncated": not readhered and not failsafe,
            "redetect_t": redetect_t,
        }
        ep = SlipEpisode(
            kind=kind,
            t_detect=float(t[det]),
            t_start=0.0,
            t_end=0.0,
            i_start=i0 - self.D,
            i_end=ie - self.D,
            d_pulse_m=0.0,
            d_corrected_m=0.0,
            max_error_m=slip_budget_m(duration, cfg.delta_a_mps2),
            readhered=readhered,
            failsafe=failsafe,
            detail=detail,
        )
        return ep, v_in

    # ------------------------------------------------------------------ output
    def assemble(self, found: list[tuple[SlipEpisode, FloatArray]], radar: FloatArray | None = None) -> Odometry:
        n, t = self.n, self.t
        d_pulse, v_pulse = self.d_pulse, self.v_pulse
        v = v_pulse.copy()
        slipping = np.zeros(n, dtype=bool)
        off_step = np.zeros(n + 1)
        allow_step = np.zeros(n + 1)
        seg_d: list[tuple[int, FloatArray]] = []
        growth: list[tuple[int, int, float]] = []
        offset = 0.0
        da = self.cfg.delta_a_mps2
        for ep, v_in in found:
            s, e = ep.i_start, ep.i_end
            if ep.detail["truncated"] and e < n - 1:  # data ended mid-correction: hold the speed
                v_in = np.concatenate([v_in, np.full(n - 1 - e, v_in[-1])])
                e = n - 1
                ep.i_end = e
            use_radar = radar is not None and bool(np.isfinite(radar[s : e + 1]).all())
            if use_radar:
                assert radar is not None
                v_in = radar[s : e + 1].astype(float)
            ep.detail["speed_source"] = "radar" if use_radar else "inertial"
            d_s = d_pulse[s] + offset
            inc = np.concatenate([[0.0], v_in[1:] * self.dt[s + 1 : e + 1]])
            d_seg = d_s + np.cumsum(inc)
            seg_d.append((s, d_seg))
            v[s + 1 : e + 1] = v_in[1:]
            slipping[s + 1 : e + 1] = True
            new_offset = float(d_seg[-1] - d_pulse[e])
            off_step[e + 1] += new_offset - offset
            offset = new_offset
            budget = slip_budget_m(float(t[e] - t[s]), da)
            if use_radar:
                budget = min(budget, RADAR_ERROR_PCT / 100.0 * float(d_seg[-1] - d_seg[0]) + RADAR_ERROR_M)
            allow_step[e + 1] += budget
            growth.append((s, e, budget))
            ep.t_start, ep.t_end = float(t[s]), float(t[e])
            ep.max_error_m = budget
            ep.d_pulse_m = float(d_pulse[e] - d_pulse[s])
            ep.d_corrected_m = float(d_seg[-1] - d_seg[0])
        d = d_pulse + np.cumsum(off_step)[:n]
        allowance = np.cumsum(allow_step)[:n]
        for (s, d_seg), (_, e, budget) in zip(seg_d, growth, strict=True):
            d[s : e + 1] = d_seg
            grow = 0.5 * da * (t[s + 1 : e + 1] - t[s]) ** 2
            allowance[s + 1 : e + 1] += np.minimum(grow, budget)
        return Odometry(d, v, slipping, allowance, [ep for ep, _ in found])


def _bridge(x: npt.NDArray[np.float64], fill: float = 0.0) -> FloatArray:
    """Linear interpolation over missing cycles (edges held; ``fill`` when all missing)."""
    ok = np.isfinite(x)
    if ok.all():
        return x.astype(float, copy=True)
    if not ok.any():
        return np.full(x.size, fill)
    idx = np.arange(x.size)
    return np.interp(idx, idx[ok], x[ok])


def _tail(weights: FloatArray) -> FloatArray:
    """Tail sums S_l = Σ_{m≥l} w_m of weights on lags 0..M−1 (S_M = 0 appended)."""
    return np.concatenate([np.cumsum(weights[::-1])[::-1], [0.0]])


def _lsq_accel_weights(m: int, dt: float) -> tuple[FloatArray, FloatArray]:
    """Weights (c, g), oldest sample first, of the least-squares acceleration over m cycles.

    ``c·d`` is the second-order coefficient of a quadratic fitted to m pulse distances:
    it uses every sample, so its quantisation error is ≈ 10× smaller than that of a
    difference of two speeds. ``g·a`` applies the *same* functional to cycle-mean
    accelerations (d_j − d_{j−1} = v_j·dt, v_j − v_{j−1} = ½(a_{j−1} + a_j)·dt), so
    ``g·a_x − c·d`` is exactly the g-weighted mean of G·sinθ for any speed profile.
    """
    tau = (np.arange(m) - (m - 1) / 2) * dt
    x = np.stack([np.ones(m), tau, 0.5 * tau**2], axis=1)
    c = np.linalg.pinv(x)[2]
    c1 = np.cumsum(c[::-1])[::-1]  # Σ_{j≥k} c_j
    c2 = np.cumsum(c1[::-1])[::-1]  # Σ_{k'≥k} c1_k'
    g = np.zeros(m)
    g[:-1] += 0.5 * c2[1:]
    g[1:] += 0.5 * c2[1:]
    return c, g * dt * dt


def _ma(x: FloatArray, window: int) -> FloatArray:
    """Trailing moving average (``cycles.moving_average``, one cumsum when x has no NaN)."""
    if window <= 1 or not np.isfinite(x).all():
        return moving_average(x, window)
    cs = np.empty(x.size + 1)
    cs[0] = 0.0
    np.cumsum(x, out=cs[1:])
    out = np.empty(x.size)
    w = min(window, x.size)
    out[:w] = cs[1 : w + 1] / np.arange(1, w + 1)
    out[w:] = (cs[w + 1 :] - cs[1 : x.size - w + 1]) / w
    return out
