"""The km filter of the possession check: km and its uncertainty from map-matched fixes
(and a tacho, when there is one) [S001 §3.2(b), §7.3].

**State and prediction.** A 1-D constant-velocity Kalman filter along the line's
kilometrage, state x = (km, v = dkm/dt), covariance P, white acceleration noise
q = ``accel_noise_mps2``²; over dt::

    F = [[1, dt], [0, 1]],   Q = q·[[dt³/3, dt²/2], [dt²/2, dt]],   x ← F x,   P ← F P Fᵀ + Q

with the speed kept within ± ``max_speed_mps``. Between fixes the filter predicts (dead
reckoning on its velocity): with 1 Hz GPS this gives the alarms their timing, as the band is
evaluated every ``step_s`` (0.1 s).

**Measurements.** A map-matched fix (km of the foot of the perpendicular on the nearest GIS
segment, :mod:`dbtools.gis.matching`, within ``max_offset_m`` of a track of the line) is
z = km with H = [1, 0]. Its error is split (:func:`km_noise`) into a white part (the
filter's R) and a slow part (bias) that no filter can average out:

=====================================  ===========================================  ==============
fix                                    white σ                                      bias σ
=====================================  ===========================================  ==============
trusted (5/15/30 s RMS filter)         ``noise_white_m`` of the GPS model (0.25 m)  ``noise_sigma_m`` (0.75 m)
usable D-GPS, not trusted              max(``untrusted_sigma_m``, 5 s RMS / √12)     ``noise_sigma_m``
fix 1 or high HDOP                     max(``untrusted_sigma_m``, 5 s RMS)           ``fix1_sigma_m`` (5 m)
=====================================  ===========================================  ==============

No RMS history yet (after a gap) counts as ``untrusted_sigma_m`` on D-GPS and as
``fix1_sigma_m`` without. The RMS of 2-D second differences is √12 × the per-axis white
noise that makes it; a multipath burst's offset is no white noise, so on D-GPS the gate, not
a wider R, keeps it out, while without D-GPS the slow error makes the gate wide and R stays
the whole RMS. The white σ is at least the fix's offset from the nearest track beyond
``offset_free_m`` (an on-rail fix far from every track is probably as wrong along it).

**Update and bias.** With innovation y = z − km⁻ and S = P00 + R, the gain is
K = (P00, P01)/S; the estimate carries the bias variance

    bvar ← (1 − K0)·bvar + K0·bias²

(the biases of the fixes it is made of, weighted as the filter weights them, as if fully
correlated), and the band is

    u(t) = gis_uncertainty_m + km_z · √(P00(t) + bvar)      (≈ 2.9 m on trusted fixes)

**Gate and restart.** A fix with y² > ``gate_z``² · (S + bvar + bias²) is rejected
(multipath); ``restart_fixes`` consecutive rejected fixes on a straight line (RMS residual
within 1.5 × their noise) at a possible speed restart the filter from that line, so that a
burst that slipped through cannot leave it lost (:func:`_restart`).

**Anchor.** A trusted fix anchors the filter for ``restart_anchor_s``: meanwhile a restart
needs a line the vehicle could have joined from the anchored state accelerating by at most
``restart_accel_mps2`` (:func:`_reachable`), and while the anchor shows the vehicle standing
(|v| < ``min_speed_mps``) a fix whose bias variance exceeds P00 + bvar (fix 1, high HDOP) is
skipped — it could only widen the band, and the gate with it.

**Tacho** (:mod:`fieldlogs.possession.tacho`). The dynamics run on the *moving time* (time
outside standstills): in a standstill no prediction and no process noise, so the band cannot
grow. A standstill's start is a perfect measurement v = 0 (:func:`_stop`: km moves back along
its correlation with the speed, P01 = P11 = 0); a fix there whose bias variance exceeds the
estimate's is skipped, and rejected fixes never restart the filter while stopped (the speed
is known, so agreeing outliers are a steady multipath offset). Moving, a tacho speed vt is a
measurement of v with H = [0, 1], z = vt signed as the predicted speed and
R = (``tacho_scale_sigma``·vt + ``tacho_speed_floor_mps``)², used only when that sign is sure
(|v| ≥ ``km_z``·σv and ≥ ``min_speed_mps``). Departure from a train's odometry on purpose:
the cab direction is not used for the sign, as it gives the km direction only through the
vehicle's facing, which no log holds.

Why these rules and values: bench/NOTES.md, "Possession".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.possession.config import PossessionConfig
from fieldlogs.possession.tacho import Tacho

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
#: (km, speed, P00, P11, moving time) of the last accepted trusted fix.
Anchor = tuple[float, float, float, float, float]
#: (km, speed, P00, P01, P11) of the filter.
State5 = tuple[float, float, float, float, float]

FIX, SPEED, HOLD = 2, 1, 0
"""Event kinds of the km filter; at one time a standstill starts first, then speed, then fix."""
#: The km filter's anchor before any trusted fix, and after a restart: never in force.
_NO_ANCHOR: Anchor = (0.0, 0.0, 0.0, 0.0, -math.inf)


@dataclass
class KmTrack:
    """Kalman-filter states after each accepted fix — and, with a tacho, after each tacho
    speed and standstill start (module docstring)."""

    t: FloatArray
    km: FloatArray
    v: FloatArray
    p00: FloatArray
    p01: FloatArray
    p11: FloatArray
    bvar: FloatArray
    """Variance of the slow (bias) GPS error carried by the estimate [m²]."""
    trusted: BoolArray
    q: float
    n_rejected: int = 0
    tacho: Tacho | None = None
    tau: FloatArray | None = None
    """With a tacho: the moving time (:meth:`Tacho.moving_time`) of each state."""
    fix_t: FloatArray | None = None
    """With a tacho: the time of the last accepted fix at each state."""

    def at(self, tq: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """(km, speed, km σ, seconds since the last accepted fix) predicted at ``tq``; NaN before
        the first fix. The prediction runs on the moving time: it stands still in a standstill."""
        tq = np.asarray(tq, dtype=float)
        if self.t.size == 0:
            nan = np.full(tq.shape, np.nan)
            return nan, nan, nan, nan
        j = np.searchsorted(self.t, tq, side="right") - 1
        ok = j >= 0
        jj = np.clip(j, 0, None)
        dt = np.where(ok, tq - self.t[jj], np.nan)
        since = dt
        if self.tacho is not None and self.tau is not None and self.fix_t is not None:
            dt = np.where(ok, self.tacho.moving_time(tq) - self.tau[jj], np.nan)
            since = np.where(ok, tq - self.fix_t[jj], np.nan)
        km = self.km[jj] + self.v[jj] * dt
        var = self.p00[jj] + 2 * dt * self.p01[jj] + dt * dt * self.p11[jj] + self.q * dt**3 / 3.0
        sig = np.sqrt(var + self.bvar[jj])
        return np.where(ok, km, np.nan), np.where(ok, self.v[jj], np.nan), np.where(ok, sig, np.nan), since


@dataclass(frozen=True)
class _Events:
    """The filter's events in time order: kind (FIX, SPEED, HOLD), index into its source,
    time, moving time, whether in a standstill; and the moving time of every fix."""

    kind: npt.NDArray[np.int8]
    idx: npt.NDArray[np.int64]
    t: FloatArray
    tau: FloatArray
    hold: BoolArray
    fix_tau: FloatArray


def _events(t: FloatArray, tacho: Tacho | None) -> _Events:
    n = t.size
    if tacho is None:
        return _Events(np.full(n, FIX, dtype=np.int8), np.arange(n), t, t, np.zeros(n, dtype=bool), t)
    kind = np.repeat(np.array([FIX, SPEED, HOLD], dtype=np.int8), [n, tacho.t.size, len(tacho.hold)])
    idx = np.concatenate([np.arange(n), np.arange(tacho.t.size), np.arange(len(tacho.hold))])
    et = np.concatenate([t, tacho.t, tacho.hold[:, 0]])
    order = np.lexsort((kind, et))
    kind, idx, et = kind[order], idx[order], et[order]
    return _Events(kind, idx, et, tacho.moving_time(et), tacho.holding(et), tacho.moving_time(t))


class _Filter:
    """The sequential part of :func:`track_km`: one event at a time, states recorded after
    each event that changed them."""

    def __init__(
        self,
        meas: tuple[FloatArray, FloatArray, FloatArray, FloatArray, BoolArray],
        cfg: PossessionConfig,
        tacho: Tacho | None,
        ev: _Events,
    ) -> None:
        self.t, self.z, self.white, self.bias, self.trusted = meas
        self.cfg, self.tacho, self.ev = cfg, tacho, ev
        self.q = cfg.accel_noise_mps2**2
        ne = ev.t.size
        self.out = {k: np.empty(ne) for k in ("t", "km", "v", "p00", "p01", "p11", "bvar", "tau", "fix_t")}
        self.tr = np.zeros(ne, dtype=bool)
        self.m = 0
        self.rejected = 0
        self.run: list[int] = []  # consecutive rejected fixes
        self.x0 = self.x1 = self.p00 = self.p01 = self.p11 = self.bv = 0.0
        self.tau_last = self.t_fix = -np.inf
        self.anchor = _NO_ANCHOR
        self.last_trusted = False

    def run_all(self) -> KmTrack:
        kinds = self.ev.kind
        for e in range(kinds.size):
            changed = self._fix(e) if kinds[e] == FIX else self._tacho(e)
            if changed:
                self._record(e)
        return self._track()

    def _predict(self, e: int) -> tuple[float, float, float, float]:
        return _predict(self.x0, self.x1, self.p00, self.p01, self.p11, float(self.ev.tau[e]) - self.tau_last, self.q)

    def _tacho(self, e: int) -> bool:
        """A standstill start (v = 0 exactly) or a tacho speed (|v| measured, signed by the filter)."""
        if self.m == 0:
            return False
        y0, c00, c01, c11 = self._predict(e)
        if self.ev.kind[e] == HOLD:
            self.x0, self.x1, self.p00, self.p01, self.p11 = _stop(y0, self.x1, c00, c01, c11)
            return True
        assert self.tacho is not None
        cfg, x1 = self.cfg, self.x1
        vt = float(self.tacho.speed[int(self.ev.idx[e])])
        if vt > cfg.tacho_speed_floor_mps and abs(x1) < max(cfg.min_speed_mps, cfg.km_z * math.sqrt(c11)):
            return False  # moving, direction not sure yet: the fixes must tell it first
        # H = [0, 1], z = |v| signed as the predicted speed, R = (scale·|v| + floor)²
        s = c11 + (cfg.tacho_scale_sigma * vt + cfg.tacho_speed_floor_mps) ** 2
        k0, k1 = c01 / s, c11 / s
        innov = math.copysign(vt, x1) - x1
        self.x0 = y0 + k0 * innov
        self.x1 = min(max(x1 + k1 * innov, -cfg.max_speed_mps), cfg.max_speed_mps)
        self.p00, self.p01, self.p11 = c00 - k0 * c01, (1 - k1) * c01, (1 - k1) * c11
        return True

    def _fix(self, e: int) -> bool:
        """A map-matched fix: the first starts the filter; later ones are gated, then fused or
        rejected (and may restart the filter)."""
        i = int(self.ev.idx[e])
        r = float(self.white[i]) ** 2
        b2 = float(self.bias[i]) ** 2
        if self.m == 0:
            self._start(e, float(self.z[i]), r, b2)
        elif float(self.t[i]) - self.t_fix <= 0 or not self._update(e, i, r, b2):
            return False
        self.t_fix = float(self.t[i])
        self.last_trusted = bool(self.trusted[i])
        return True

    def _start(self, e: int, z: float, r: float, b2: float) -> None:
        self.x0, self.x1 = z, 0.0
        self.p00, self.p01, self.p11, self.bv = r, 0.0, self.cfg.speed_sigma_mps**2, b2
        if self.ev.hold[e]:
            self.x0, self.x1, self.p00, self.p01, self.p11 = _stop(self.x0, self.x1, self.p00, self.p01, self.p11)

    def _update(self, e: int, i: int, r: float, b2: float) -> bool:
        """Fuse, skip or reject fix ``i``; False when the state did not change."""
        cfg, tau = self.cfg, float(self.ev.tau[e])
        y0, c00, c01, c11 = self._predict(e)
        innov = float(self.z[i]) - y0
        s = c00 + r
        anchored = tau - self.anchor[4] < cfg.restart_anchor_s
        still = anchored and abs(self.anchor[1]) < cfg.min_speed_mps
        if (self.ev.hold[e] or still) and b2 > c00 + self.bv:
            # stopped (tacho, or trusted fixes moments ago): a fix whose slow error alone is
            # worse than the estimate (fix 1, high HDOP) would only widen the band — and the
            # gate with it, for the multipath burst that made it
            return False
        if innov * innov > cfg.gate_z**2 * (s + self.bv + b2):
            return self._reject(e, i, anchored)
        self.run = []
        k0, k1 = c00 / s, c01 / s
        self.x0 = y0 + k0 * innov
        self.x1 = min(max(self.x1 + k1 * innov, -cfg.max_speed_mps), cfg.max_speed_mps)
        self.p00, self.p01, self.p11 = (1 - k0) * c00, (1 - k0) * c01, c11 - k1 * c01
        self.bv = (1 - k0) * self.bv + k0 * b2
        if self.trusted[i]:
            self.anchor = (self.x0, self.x1, self.p00, self.p11, tau)
        return True

    def _reject(self, e: int, i: int, anchored: bool) -> bool:
        """An outlier (multipath): the state stays the prediction from the last accepted fix —
        unless the rejected fixes agree among themselves, i.e. the filter lost the vehicle (a
        burst that slipped through bent its speed): restart from them. Not in a standstill:
        the speed is known there, so it cannot have been bent."""
        self.rejected += 1
        self.run.append(i)
        if self.ev.hold[e]:
            return False
        prior = self.anchor if anchored else None
        restart = _restart(self.ev.fix_tau, self.z, self.white, self.bias, self.run, self.cfg, prior)
        if restart is None:
            return False
        self.x0, self.x1, self.p00, self.p01, self.p11, self.bv = restart
        self.anchor = _NO_ANCHOR
        self.run = []
        return True

    def _record(self, e: int) -> None:
        m, out = self.m, self.out
        self.tau_last = float(self.ev.tau[e])
        out["t"][m], out["km"][m], out["v"][m] = float(self.ev.t[e]), self.x0, self.x1
        out["p00"][m], out["p01"][m], out["p11"][m], out["bvar"][m] = self.p00, self.p01, self.p11, self.bv
        out["tau"][m], out["fix_t"][m] = self.tau_last, self.t_fix
        self.tr[m] = self.last_trusted
        self.m += 1

    def _track(self) -> KmTrack:
        m, out, with_tacho = self.m, self.out, self.tacho is not None
        return KmTrack(
            out["t"][:m],
            out["km"][:m],
            out["v"][:m],
            out["p00"][:m],
            out["p01"][:m],
            out["p11"][:m],
            out["bvar"][:m],
            self.tr[:m],
            self.q,
            self.rejected,
            self.tacho,
            out["tau"][:m] if with_tacho else None,
            out["fix_t"][:m] if with_tacho else None,
        )


def track_km(
    t: FloatArray,
    z: FloatArray,
    white: FloatArray,
    bias: FloatArray,
    trusted: BoolArray,
    cfg: PossessionConfig,
    tacho: Tacho | None = None,
) -> KmTrack:
    """Run the constant-velocity filter over the km measurements (sorted by t).

    ``white``: σ of the independent part of each measurement (the filter's R); ``bias``: σ
    of its slow part — the estimate carries bvar ← (1 − K)·bvar + K·bias² (module docstring).
    ``tacho`` (on-rail part only): standstills hold the filter, speeds measure |dkm/dt|
    (module docstring).
    """
    return _Filter((t, z, white, bias, trusted), cfg, tacho, _events(t, tacho)).run_all()


def _predict(
    x0: float, x1: float, p00: float, p01: float, p11: float, dt: float, q: float
) -> tuple[float, float, float, float]:
    """Constant-velocity prediction over dt: F = [[1, dt], [0, 1]], Q = q·[[dt³/3, dt²/2],
    [dt²/2, dt]]; returns (km, P00, P01, P11) (the speed is unchanged)."""
    return (
        x0 + x1 * dt,
        p00 + 2 * dt * p01 + dt * dt * p11 + q * dt**3 / 3.0,
        p01 + dt * p11 + q * dt * dt / 2.0,
        p11 + q * dt,
    )


def _stop(x0: float, x1: float, p00: float, p01: float, p11: float) -> State5:
    """The update by a perfect measurement speed = 0 (a standstill): km moves back along its
    correlation with the speed, and the speed and its variance become 0."""
    if p11 > 0.0:
        x0, p00 = x0 - p01 / p11 * x1, max(p00 - p01 * p01 / p11, 0.0)
    return x0, 0.0, p00, 0.0, 0.0


def _restart(
    t: FloatArray,
    z: FloatArray,
    white: FloatArray,
    bias: FloatArray,
    run: list[int],
    cfg: PossessionConfig,
    prior: Anchor | None = None,
) -> tuple[float, float, float, float, float, float] | None:
    """A new state from the last ``restart_fixes`` rejected fixes when a straight line fits
    them within 1.5 × their noise at a possible speed — and, given an anchored ``prior``
    (km, speed, P00, P11, time), one the vehicle could have joined (:func:`_reachable`);
    None otherwise. The new P00 is resid² + noise², P11 = max(1, 2·P00 / Σ(t − t_last)²)."""
    k = cfg.restart_fixes
    if k < 2 or len(run) < k:
        return None
    idx = np.array(run[-k:])
    tt = t[idx] - t[idx[-1]]
    zz = z[idx]
    a = np.vstack([np.ones(k), tt]).T
    coef, *_ = np.linalg.lstsq(a, zz, rcond=None)
    resid = float(np.sqrt(np.mean((zz - a @ coef) ** 2)))
    noise = max(1.0, float(np.median(white[idx])))
    if resid > 1.5 * noise or abs(coef[1]) > cfg.max_speed_mps:
        return None
    if prior is not None and not _reachable(tt + float(t[idx[-1]]), coef, resid, prior, cfg.restart_accel_mps2):
        return None
    p00 = resid**2 + noise**2
    p11 = max(1.0, 2.0 * p00 / max(float(np.sum(tt**2)), 1.0))
    return float(coef[0]), float(coef[1]), p00, 0.0, p11, float(np.max(bias[idx] ** 2))


def _reachable(t: FloatArray, coef: FloatArray, resid: float, prior: Anchor, accel: float) -> bool:
    """Could a vehicle in the state ``prior`` = (km, speed, P00, P11, time) have joined the
    line ``coef`` = (km at t[-1], speed) by its first fix t[0], accelerating by at most
    ``accel``? Speed and position each within 3σ (the prior's and the line's, the line's
    per-fix error its RMS residual, at least 0.5 m) plus what that acceleration allows:
    |v1 − v0| ≤ a·dt + 3σv and |z1 − (x0 + (v0 + v1)·dt/2)| ≤ a·dt²/4 + 3σz."""
    x0, v0, p00, p11, t0 = prior
    k = t.size
    dt = max(float(t[0]) - t0, 0.0)
    s2 = max(resid * resid, 0.25)
    tc = t - t.mean()
    sxx = max(float(np.sum(tc * tc)), 1e-9)
    v_var = s2 / sxx
    z_var = s2 * (1.0 / k + float(tc[0]) ** 2 / sxx)
    v1 = float(coef[1])
    z1 = float(coef[0]) + v1 * float(t[0] - t[-1])
    speed_ok = abs(v1 - v0) <= accel * dt + 3.0 * math.sqrt(max(p11, 0.0) + v_var)
    z_sd = math.sqrt(max(p00, 0.0) + 0.25 * dt * dt * (max(p11, 0.0) + v_var) + z_var)
    place_ok = abs(z1 - (x0 + 0.5 * (v0 + v1) * dt)) <= 0.25 * accel * dt * dt + 3.0 * z_sd
    return speed_ok and place_ok


def bool_column(frame: pd.DataFrame, name: str) -> BoolArray:
    """A boolean column, False where missing (all False without the column)."""
    if name not in frame.columns:
        return np.zeros(len(frame), dtype=bool)
    out: BoolArray = frame[name].fillna(False).to_numpy(dtype=bool)
    return out


def km_noise(fixes: pd.DataFrame, gps_cfg: GpsConfig, cfg: PossessionConfig) -> tuple[FloatArray, FloatArray]:
    """(white σ, bias σ) of the km of each fix (module docstring, the table)."""
    n = len(fixes)
    rms_cols = sorted((c for c in fixes.columns if c.startswith("rms_")), key=lambda c: float(c[4:]))
    # the shortest window: the quality of the last seconds
    rms = fixes[rms_cols[0]].to_numpy(dtype=float, na_value=np.nan) if rms_cols else np.full(n, np.nan)
    off = np.abs(fixes["offset_m"].to_numpy(dtype=float, na_value=np.nan)) if "offset_m" in fixes else np.zeros(n)
    trusted = bool_column(fixes, "trusted")
    dgps = bool_column(fixes, "usable") | trusted
    # an on-rail fix far from the track is as wrong along the track, likely: the offset bounds σ
    excess = np.fmax(off - cfg.offset_free_m, 0.0)
    bias = np.where(dgps, gps_cfg.noise_sigma_m, cfg.fix1_sigma_m)
    # the RMS of 2-D second differences is √12 × the per-axis white noise that makes it; a
    # D-GPS fix's burst offset is no white noise: the gate, not a wider R, must keep it out.
    # Without D-GPS (fix 1, high HDOP) the slow error is large and the gate wide: keep R wide.
    scale = np.where(dgps, 1.0 / np.sqrt(12.0), 1.0)
    # no RMS history yet (after a gap): a D-GPS fix is as good as D-GPS usually is — the gate
    # keeps out the bad ones; without D-GPS nothing is known
    unknown = np.where(dgps, cfg.untrusted_sigma_m, cfg.fix1_sigma_m)
    noisy = np.fmax(cfg.untrusted_sigma_m, np.where(np.isfinite(rms), rms * scale, unknown))
    white = np.fmax(np.where(trusted, gps_cfg.noise_white_m, noisy), excess)
    return white, bias
