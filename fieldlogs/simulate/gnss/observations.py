"""GNSS observation simulator: pseudoranges of two (or more) antennas on a moving vehicle.

Driven by a vehicle trajectory — reference-point ECEF, heading (clockwise from north) and
along-track position s per epoch, as the train simulator's truth provides — and by the
broadcast ephemerides of ``constellation`` (the satellites' true positions come from the same
records; solver and simulator share only the ICD algorithm, which the independent-library
test checks). For each receiver, epoch and satellite:

* antenna A = ref + R_ENU→ECEF·(f·(sin ψ, cos ψ, 0) + l·(−cos ψ, sin ψ, 0) + u·(0, 0, 1));
* light time by iteration: τ = |R₃(Ω̇e τ)·r_s(t − τ) − A|/c, the satellite's ECEF position
  at transmission rotated into the frame of reception (the exact Earth rotation the solvers
  model to first order with the Sagnac term);
* ρ = c·τ + c·(b_r − Δt_sv,f) + ε_sis + I + T + m + n (+ a reflection bias for NLOS):
  b_r receiver clock (bias, drift, random walk), Δt_sv,f the broadcast clock with the group
  delay, ε_sis the signal-in-space error (Gauss–Markov, σ per system, τ 30 min, common to
  all receivers), I the true ionosphere = Klobuchar × (1 + run scale) × (1 + per-satellite
  scale), T = Saastamoinen × (1 + run scale), m multipath (Gauss–Markov by receiver and
  satellite, σ growing at low elevation and beside buildings), n white code noise whose σ
  follows C/N0 (0.3 m at 45 dB-Hz); with ``reflectors`` (a surface beside the track, per
  antenna arc length s + direction·f) the reflection's code, carrier and C/N0 errors of
  :mod:`fieldlogs.simulate.gnss.reflection` besides, drawn from their own generator (a run
  without reflectors keeps every other draw);
* C/N0 = 33 + 14 sin E dB-Hz + N(0, 1), 3 dB less beside buildings, 8 dB less for NLOS;
* the sky by side: ``Corridor`` sections (buildings on the left or right up to an
  elevation, cuttings on both sides, overpasses and tunnels that block everything) as
  functions of s; a satellite behind buildings is received by reflection (NLOS) with
  probability ``p_nlos`` per pass, with an exponential extra delay (mean ``nlos_mean_m``);
* receiver time tag gnss_time_s = t + b_r (the receiver's clock), carrier phase and Doppler
  consistent with the same geometry (Doppler = −(ρ̇ + c(ḃ − Δṫ_sv))/λ); the carrier advances
  the ionosphere (−I), carries 1 % of the code multipath, the NLOS extra path and 3 mm noise,
  with one integer ambiguity per satellite.

D-GPS-level corrections (``dgps_corrections``): per epoch and satellite PRC = −(ε_sis + I + T)
plus the reference-station residual: 5 % of the atmospheric delays (decorrelation over a
few km) and white N(0, 0.15 m) — residual errors at the decimetre level.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from fieldlogs.gnss.atmosphere import klobuchar_s, tropo_delay_m
from fieldlogs.gnss.constants import C_MPS, F_L1_HZ, OBS_COLUMNS, FloatArray, IntArray, system_of
from fieldlogs.gnss.ephemeris import NavTable, group_delay_s, nav_table, satellite_states, select_ephemeris
from fieldlogs.gnss.geodesy import azimuth_elevation, ecef_to_geodetic, enu_basis, geodetic_to_ecef
from fieldlogs.simulate.gnss.reflection import ReflectionErrors, ReflectorsAt, phase_walk, reflection_errors

KLOBUCHAR_ALPHA = (1.1176e-08, 7.4506e-09, -5.9605e-08, -5.9605e-08)
KLOBUCHAR_BETA = (90112.0, 0.0, -196608.0, -65536.0)
"""Typical broadcast Klobuchar parameters (mid solar activity)."""


@dataclass(frozen=True)
class ReceiverSpec:
    """One receiver and its antenna on the vehicle (forward, left, up from the reference point)."""

    name: str
    forward_m: float = 0.0
    left_m: float = 0.0
    up_m: float = 3.8
    clock_bias_s: float = 1e-4
    clock_drift_sps: float = 5e-9
    clock_walk_m: float = 0.1
    """Random-walk σ of the clock [m/√s]."""


@dataclass(frozen=True)
class Section:
    """A stretch [s_from, s_to) of blocked sky: kind 'left', 'right', 'cutting', 'overpass' or 'tunnel'."""

    s_from: float
    s_to: float
    kind: str
    elevation_deg: float = 90.0


@dataclass(frozen=True)
class Corridor:
    """Blocked sky along the track (module docstring)."""

    sections: tuple[Section, ...] = ()

    def masks(self, s: FloatArray) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray]:
        """(left mask elevation, right mask elevation [deg], all blocked, beside buildings) per s."""
        s = np.asarray(s, dtype=float)
        left = np.zeros(s.shape)
        right = np.zeros(s.shape)
        blocked = np.zeros(s.shape, dtype=bool)
        buildings = np.zeros(s.shape, dtype=bool)
        for sec in self.sections:
            inside = (s >= sec.s_from) & (s < sec.s_to)
            if sec.kind in ("overpass", "tunnel"):
                blocked |= inside
            if sec.kind in ("left", "cutting"):
                left = np.where(inside, np.maximum(left, sec.elevation_deg), left)
            if sec.kind in ("right", "cutting"):
                right = np.where(inside, np.maximum(right, sec.elevation_deg), right)
            if sec.kind in ("left", "right"):
                buildings |= inside
        return left, right, blocked, buildings


@dataclass(frozen=True)
class ErrorSpec:
    """Truth error magnitudes (module docstring) [m unless named]."""

    sis_sigma_m: dict[str, float] = field(default_factory=lambda: {"G": 0.6, "E": 0.3, "J": 0.6})
    sis_tau_s: float = 1800.0
    iono_run_sigma: float = 0.35
    iono_sat_sigma: float = 0.1
    tropo_run_sigma: float = 0.03
    mp_zenith_m: float = 0.2
    mp_low_m: float = 1.5
    mp_scale_deg: float = 12.0
    mp_tau_s: float = 3.0
    mp_buildings_factor: float = 1.5
    noise_45_m: float = 0.3
    p_nlos: float = 0.1
    nlos_mean_m: float = 20.0
    min_elevation_deg: float = 5.0
    orbit_sigma_m: float = 0.0
    """Broadcast orbit error per ECEF axis (constant + drift per satellite), 0: none. Only a
    run written with an SBAS stream sets it (``fieldlogs.simulate.gnss.sbas_stream``): the long-term
    corrections then have something to remove; drawn from its own generator, so the other
    error components of a seed stay the same."""
    orbit_rate_sigma_mps: float = 0.0
    clock_sigma_m: float = 0.0
    """Broadcast clock error (c·δΔt, constant + drift per satellite), 0: none."""
    clock_rate_sigma_mps: float = 0.0


def with_sat_errors(err: ErrorSpec) -> ErrorSpec:
    """``err`` plus broadcast orbit (1 m per axis, 0.5 mm/s) and clock (1 m, 0.2 mm/s) errors per
    satellite, as a run written with an SBAS stream has them."""
    return replace(err, orbit_sigma_m=1.0, orbit_rate_sigma_mps=5e-4, clock_sigma_m=1.0, clock_rate_sigma_mps=2e-4)


@dataclass
class Trajectory:
    """Vehicle truth per epoch: t (run clock = GPS time here), reference ECEF, heading, s, direction."""

    t: FloatArray
    ref_ecef: FloatArray
    heading_rad: FloatArray
    s: FloatArray
    direction: FloatArray

    @classmethod
    def from_geodetic(
        cls,
        t: FloatArray,
        lat_deg: FloatArray,
        lon_deg: FloatArray,
        h_m: FloatArray,
        heading_deg: FloatArray,
        s: FloatArray,
        direction: FloatArray | float = 1.0,
    ) -> Trajectory:
        """From latitude/longitude/ellipsoidal height and heading (clockwise from north) per epoch,
        as the train simulator's truth gives them."""
        t = np.asarray(t, dtype=float)
        ecef = geodetic_to_ecef(np.radians(lat_deg), np.radians(lon_deg), h_m)
        d = np.broadcast_to(np.asarray(direction, dtype=float), t.shape).copy()
        return cls(t, ecef, np.radians(np.asarray(heading_deg, dtype=float)), np.asarray(s, dtype=float), d)


@dataclass
class Simulated:
    """Frames and truth of one simulated run."""

    obs: pd.DataFrame
    nav: pd.DataFrame
    iono: dict[str, tuple[float, ...]]
    truth: pd.DataFrame
    """Per receiver × epoch: antenna ECEF, clock bias [m], s."""
    rows: pd.DataFrame
    """Per observation: the error components (sis, iono, tropo, multipath, noise, nlos, the
    reflection's code error) [m]."""
    truth_errors: SatErrors | None = None
    """Per epoch and satellite, the errors an augmentation could know (SBAS simulator)."""


@dataclass(frozen=True)
class SatErrors:
    """Satellite-side truth of a simulated run on the epoch grid ``t`` × ``sats``: the SIS range
    error [m], the broadcast orbit error δr (t, s, 3) [m] and clock error c·δΔt [m] (the true
    satellite is at r_brdc + δr, its clock Δt_brdc + δΔt), the ionosphere's run scale."""

    t: FloatArray
    sats: np.ndarray
    sis_m: FloatArray
    orbit_m: FloatArray
    clock_m: FloatArray
    iono_run_scale: float


def antenna_positions(traj: Trajectory, rx: ReceiverSpec) -> FloatArray:
    """ECEF of the antenna at every epoch (module docstring)."""
    lat, lon, _ = ecef_to_geodetic(traj.ref_ecef)
    r = enu_basis(lat, lon)
    h = traj.heading_rad
    enu = (
        rx.forward_m * np.stack([np.sin(h), np.cos(h), np.zeros_like(h)], axis=-1)
        + rx.left_m * np.stack([-np.cos(h), np.sin(h), np.zeros_like(h)], axis=-1)
        + rx.up_m * np.array([0.0, 0.0, 1.0])
    )
    return np.asarray(traj.ref_ecef + np.einsum("eij,ei->ej", r, enu), dtype=float)


def _gauss_markov(rng: np.random.Generator, n_t: int, n_s: int, dt: float, tau: float, sigma: FloatArray) -> FloatArray:
    """Unit-σ first-order Gauss–Markov sequences (n_t, n_s) times sigma (n_t, n_s)."""
    a = np.exp(-dt / tau)
    x = np.empty((n_t, n_s))
    x[0] = rng.standard_normal(n_s)
    drive = rng.standard_normal((n_t, n_s)) * np.sqrt(1.0 - a * a)
    for i in range(1, n_t):  # sequential by nature (a recursion in time); n_t ≤ a few thousand
        x[i] = a * x[i - 1] + drive[i]
    return np.asarray(x * sigma, dtype=float)


def _light_time(
    table: NavTable, idx: IntArray, t: FloatArray, ant: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Transmission position rotated into the reception frame, geometric range, sat velocity."""
    tau = np.full(t.shape, 0.075)
    we = 7.2921151467e-5
    for _ in range(4):
        st = satellite_states(table, idx, t - tau)
        th = we * tau
        c, s = np.cos(th), np.sin(th)
        x, y, z = st.pos[..., 0], st.pos[..., 1], st.pos[..., 2]
        rot = np.stack([c * x + s * y, -s * x + c * y, z], axis=-1)
        tau = np.linalg.norm(rot - ant, axis=-1) / C_MPS
    return rot, C_MPS * tau, st.vel


def simulate(
    traj: Trajectory,
    nav: pd.DataFrame,
    receivers: list[ReceiverSpec],
    corridor: Corridor,
    seed: int,
    errors: ErrorSpec | None = None,
    systems: tuple[str, ...] = ("G", "E", "J"),
    reflectors: ReflectorsAt | None = None,
) -> Simulated:
    """Simulate every receiver's ``gnss_obs`` rows along ``traj`` (module docstring)."""
    err = errors or ErrorSpec()
    rng = np.random.default_rng(seed)
    rng_refl = np.random.default_rng([seed, 0x4D50])
    table = nav_table(nav)
    sats = np.array(sorted({s for s in nav["sat"].unique() if s[0] in systems}))
    n_t, n_s = traj.t.size, sats.size
    dt = float(np.median(np.diff(traj.t))) if n_t > 1 else 1.0
    tt = np.repeat(traj.t[:, None], n_s, axis=1)
    ss = np.broadcast_to(sats, (n_t, n_s))
    idx = select_ephemeris(table, ss, tt)
    sysl = system_of(ss)
    sis = _gauss_markov(rng, n_t, n_s, dt, err.sis_tau_s, np.vectorize(lambda c: err.sis_sigma_m.get(c, 0.5))(sysl))
    iono_run = max(1.0 + rng.normal(0.0, err.iono_run_sigma), 0.2)
    iono_scale = iono_run * (1.0 + err.iono_sat_sigma * rng.standard_normal(n_s))
    orbit, clock_err = _orbit_clock_errors(err, seed, traj.t, n_s)
    tropo_scale = 1.0 + rng.normal(0.0, err.tropo_run_sigma)
    nlos_pass = rng.random(n_s) < err.p_nlos
    nlos_bias = rng.exponential(err.nlos_mean_m, n_s)
    left_m, right_m, blocked_all, buildings = corridor.masks(traj.s)
    obs_frames, truth_frames, row_frames = [], [], []
    for rx in receivers:
        ant = antenna_positions(traj, rx)
        rot, rng_m, vel = _light_time(table, idx, tt, ant[:, None, :])
        st_clock = satellite_states(table, idx, tt - rng_m / C_MPS)
        clock_f = st_clock.clock_s - group_delay_s(table, idx, np.full(tt.shape, F_L1_HZ))
        az, el = azimuth_elevation(ant[:, None, :], rot)
        lat, lon, h = ecef_to_geodetic(ant)
        iono = C_MPS * klobuchar_s(lat[:, None], lon[:, None], az, el, tt, KLOBUCHAR_ALPHA, KLOBUCHAR_BETA) * iono_scale
        tropo = tropo_delay_m(lat[:, None], h[:, None], np.maximum(el, np.radians(1.0))) * tropo_scale
        track_heading = traj.heading_rad + np.where(traj.direction < 0, np.pi, 0.0)
        right_side = np.sin(az - track_heading[:, None]) > 0  # the track's right, facing increasing s
        side_mask = np.where(right_side, right_m[:, None], left_m[:, None])
        behind = np.degrees(el) < side_mask
        visible = (
            (np.degrees(el) >= err.min_elevation_deg)
            & ~blocked_all[:, None]
            & (~behind | (nlos_pass & buildings[:, None]))
        )
        nlos = visible & behind
        mp_sigma = (err.mp_zenith_m + err.mp_low_m * np.exp(-np.degrees(el) / err.mp_scale_deg)) * np.where(
            buildings[:, None], err.mp_buildings_factor, 1.0
        )
        mp = _gauss_markov(rng, n_t, n_s, dt, err.mp_tau_s, mp_sigma)
        refl = _reflections(reflectors, traj, rx, el, az - track_heading[:, None], (dt, err.mp_tau_s), rng_refl)
        cn0 = 33.0 + 14.0 * np.sin(np.maximum(el, 0.0)) + rng.normal(0.0, 1.0, el.shape)
        cn0 = cn0 - 3.0 * buildings[:, None] - 8.0 * nlos + refl.cn0_db
        noise = err.noise_45_m * 10.0 ** ((45.0 - cn0) / 20.0) * rng.standard_normal(el.shape)
        walk = np.cumsum(rng.normal(0.0, rx.clock_walk_m * np.sqrt(dt), n_t))
        clock_m = C_MPS * (rx.clock_bias_s + rx.clock_drift_sps * (traj.t - traj.t[0])) + walk
        extra = np.where(nlos, nlos_bias[None, :], 0.0)
        pr = rng_m + clock_m[:, None] - C_MPS * clock_f + sis + iono + tropo + mp + noise + extra + refl.code_m
        lam = C_MPS / F_L1_HZ
        u = (rot - ant[:, None, :]) / rng_m[..., None]
        sat_side = 0.0
        if orbit is not None and clock_err is not None:
            sat_side = np.sum(u * orbit, axis=-1) - clock_err
            pr = pr + sat_side
        v_ant = np.gradient(ant, traj.t, axis=0) if n_t > 1 else np.zeros_like(ant)
        rate = np.sum(u * (vel - v_ant[:, None, :]), axis=-1)
        clock_rate = C_MPS * rx.clock_drift_sps - C_MPS * st_clock.clock_rate
        doppler = -(rate + clock_rate) / lam
        amb = np.round(rng.uniform(-1e6, 1e6, n_s))
        carrier_noise = 0.003 * rng.standard_normal(el.shape)
        carrier = (
            rng_m + clock_m[:, None] - C_MPS * clock_f + sis - iono + tropo + 0.01 * mp + extra + carrier_noise
        ) / lam + amb
        carrier = carrier + refl.carrier_m / lam
        if orbit is not None:
            carrier = carrier + sat_side / lam
        keep = visible & (idx >= 0)
        e_i, s_i = np.nonzero(keep)
        t_tag = traj.t + clock_m / C_MPS
        obs_frames.append(
            pd.DataFrame(
                {
                    "t": traj.t[e_i],
                    "gnss_time_s": t_tag[e_i],
                    "receiver": rx.name,
                    "sat": sats[s_i],
                    "signal": "C1C",
                    "pseudorange_m": pr[e_i, s_i],
                    "carrier_cycles": carrier[e_i, s_i],
                    "doppler_hz": doppler[e_i, s_i],
                    "cn0_dbhz": np.round(cn0[e_i, s_i], 1),
                    "lli": 0,
                }
            )
        )
        row_frames.append(
            pd.DataFrame(
                {
                    "t": traj.t[e_i],
                    "receiver": rx.name,
                    "sat": sats[s_i],
                    "sis_m": sis[e_i, s_i],
                    "iono_m": iono[e_i, s_i],
                    "tropo_m": tropo[e_i, s_i],
                    "multipath_m": mp[e_i, s_i],
                    "noise_m": noise[e_i, s_i],
                    "nlos_m": extra[e_i, s_i],
                    "reflection_m": refl.code_m[e_i, s_i],
                    "elevation_deg": np.degrees(el[e_i, s_i]),
                }
            )
        )
        truth_frames.append(
            pd.DataFrame(
                {
                    "t": traj.t,
                    "gnss_time_s": t_tag,
                    "receiver": rx.name,
                    "x_m": ant[:, 0],
                    "y_m": ant[:, 1],
                    "z_m": ant[:, 2],
                    "clock_m": clock_m,
                    "s_m": traj.s,
                }
            )
        )
    obs = pd.concat(obs_frames, ignore_index=True)[list(OBS_COLUMNS)]
    iono_params: dict[str, tuple[float, ...]] = {"gps_alpha": KLOBUCHAR_ALPHA, "gps_beta": KLOBUCHAR_BETA}
    truth_err = SatErrors(
        traj.t,
        sats,
        sis,
        orbit if orbit is not None else np.zeros((n_t, n_s, 3)),
        clock_err if clock_err is not None else np.zeros((n_t, n_s)),
        float(iono_run),
    )
    return Simulated(
        obs,
        nav,
        iono_params,
        pd.concat(truth_frames, ignore_index=True),
        pd.concat(row_frames, ignore_index=True),
        truth_err,
    )


def _reflections(
    at: ReflectorsAt | None,
    traj: Trajectory,
    rx: ReceiverSpec,
    el: FloatArray,
    rel_az: FloatArray,
    dt_tau: tuple[float, float],
    rng: np.random.Generator,
) -> ReflectionErrors:
    """The reflection errors at receiver ``rx``'s antenna (arc length s + direction·forward), all
    zero without reflectors (module docstring)."""
    if at is None:
        z = np.zeros(el.shape)
        return ReflectionErrors(z, z, z, z)
    refl = at(traj.s + traj.direction * rx.forward_m)
    phi = phase_walk(rng, el.shape[0], el.shape[1], *dt_tau)
    return reflection_errors(refl, el, rel_az, rx.up_m, phi)


def _orbit_clock_errors(
    err: ErrorSpec, seed: int, t: FloatArray, n_s: int
) -> tuple[FloatArray | None, FloatArray | None]:
    """Broadcast orbit (t, s, 3) and clock (t, s) errors [m]: per satellite a constant plus a
    drift about the run's middle; None when switched off (``ErrorSpec.orbit_sigma_m``)."""
    if err.orbit_sigma_m <= 0.0 and err.clock_sigma_m <= 0.0:
        return None, None
    rng = np.random.default_rng([seed, 0x5BA5])
    dt = (t - 0.5 * (t[0] + t[-1]))[:, None]
    r0 = rng.normal(0.0, err.orbit_sigma_m, (n_s, 3))
    v = rng.normal(0.0, err.orbit_rate_sigma_mps, (n_s, 3))
    c0 = rng.normal(0.0, err.clock_sigma_m, n_s)
    cv = rng.normal(0.0, err.clock_rate_sigma_mps, n_s)
    orbit = r0[None, :, :] + v[None, :, :] * dt[..., None]
    return np.asarray(orbit, dtype=float), np.asarray(c0[None, :] + cv[None, :] * dt, dtype=float)


def dgps_corrections(sim: Simulated, seed: int, sigma_m: float = 0.15, decorrelation: float = 0.05) -> pd.DataFrame:
    """D-GPS-level corrections frame for ``sim`` (module docstring; ``corrections`` columns)."""
    rng = np.random.default_rng(seed)
    r = sim.rows.drop_duplicates(["t", "sat"]).reset_index(drop=True)
    atm = r["iono_m"].to_numpy() + r["tropo_m"].to_numpy()
    prc = (
        -(r["sis_m"].to_numpy() + atm)
        + decorrelation * atm * rng.standard_normal(len(r))
        + rng.normal(0.0, sigma_m, len(r))
    )
    return pd.DataFrame(
        {
            "gnss_time_s": r["t"].to_numpy() - 0.5,
            "sat": r["sat"].to_numpy(),
            "prc_m": prc,
            "rrc_mps": 0.0,
            "sigma_m": np.hypot(sigma_m, decorrelation * atm) + 0.2,
            "usable": True,
            "covers_atmosphere": True,
        }
    )


def inject_fault(obs: pd.DataFrame, sat: str, t0: float, step_m: float = 0.0, ramp_mps: float = 0.0) -> pd.DataFrame:
    """A copy of ``obs`` whose ``sat`` pseudoranges (all receivers: a satellite fault) gain
    step_m + ramp_mps·(t − t0) from run time t0 on."""
    out = obs.copy()
    hit = (out["sat"] == sat) & (out["t"] >= t0)
    out.loc[hit, "pseudorange_m"] += step_m + ramp_mps * (out.loc[hit, "t"] - t0)
    return out
