"""A ``gnss_sbas`` stream consistent with a simulated run (``fieldlogs.simulate.gnss.observations``).

The GEO (MSAS PRN 137 by default) sends one message per second, encoded with the real bit
layouts and CRC (:mod:`fieldlogs.simulate.gnss.sbas_encode`). Per 6-second frame: MT 2, 3, 4 (fast
corrections of the 31 GPS satellites in mask order, fresh every 6 s), then three messages of a
rotating queue — MT 1 (PRN mask: every GPS satellite of the navigation data), MT 7 (a_i = 1:
5·10⁻⁵ m/s², 180 s time-out, t_lat 2 s), MT 10, MT 6, MT 18 per band, MT 25 (velocity code 1,
one satellite per half), MT 26 per block. The queue takes about a minute, so a stream that
starts with the run leaves the first minute uncorrected; ``lead_s`` starts it earlier (the
receiver on before the run), the truth held at its first value.

Contents, from the run's truth (``Simulated.truth_errors``), at each message's time of
applicability T:

* long-term: δr(t₀) and δṙ of the orbit error, δaf0 = c·δΔt(t₀)/c and δaf1 its rate, t₀ the
  16-s multiple nearest T, the IODE of the ephemeris a user selects at T;
* fast: PRC = −ε_sis − (c·δaf0_LTC(T) − c·δΔt(T)) + e_SBAS, e_SBAS the network's own error
  (Gauss–Markov per satellite, σ ``fast_sigma_m``, τ 120 s); UDREI 3 (σ_UDRE 0.53 m);
* grid: at each IGP of the bands under the run (±20° latitude, ±25° longitude of its mean
  position) the vertical Klobuchar delay of the IGP taken as pierce point × the run's
  ionosphere scale, quantised to 0.125 m; GIVEI the smallest whose σ_GIVE ≥ max(15 % of the
  delay, 0.3 m) (the truth's per-satellite scale of 10 % and the two models' different pierce
  points and obliquities are what remains).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import C_MPS, GPS_PI, FloatArray
from fieldlogs.gnss.ephemeris import NavTable, nav_table, select_ephemeris
from fieldlogs.gnss.geodesy import ecef_to_geodetic
from fieldlogs.gnss.sbas_tables import SIGMA2_GIVE_M2, band_igps
from fieldlogs.simulate.gnss import sbas_encode as enc
from fieldlogs.simulate.gnss.observations import KLOBUCHAR_ALPHA, KLOBUCHAR_BETA, SatErrors, Simulated

MT10_SIM = enc.Mt10(b_rrc=0.01, i_ltc_v1=300, i_ltc_v0=120, c_iono_step=0.01, i_iono=300, c_iono_ramp=5e-6)
UDREI_SIM = 3
AI_SIM = 1
IODP, IODI = 1, 1


def klobuchar_vertical_m(lat_deg: FloatArray, lon_deg: FloatArray, t_gps: float) -> FloatArray:
    """Klobuchar's vertical delay [m] with (lat, lon) taken as the pierce point (IS-GPS-200N
    Figure 20-4 without the obliquity)."""
    phi_i = np.asarray(lat_deg, dtype=float) / 180.0
    lam_i = np.asarray(lon_deg, dtype=float) / 180.0
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * GPS_PI)
    t = np.mod(4.32e4 * lam_i + t_gps, 86_400.0)
    amp = np.maximum(sum(KLOBUCHAR_ALPHA[n] * phi_m**n for n in range(4)), 0.0)
    per = np.maximum(sum(KLOBUCHAR_BETA[n] * phi_m**n for n in range(4)), 72_000.0)
    x = 2.0 * np.pi * (t - 50_400.0) / per
    v = np.where(np.abs(x) < 1.57, 5e-9 + amp * (1.0 - x**2 / 2.0 + x**4 / 24.0), 5e-9)
    return np.asarray(C_MPS * v, dtype=float)


def _givei(delay_m: FloatArray) -> list[int]:
    need = np.maximum(0.15 * np.asarray(delay_m, dtype=float), 0.3)
    sig = np.sqrt(SIGMA2_GIVE_M2[:15])
    return [int(np.argmax(sig >= n)) if np.any(sig >= n) else 14 for n in need]


def _igp_layout(lat_deg: float, lon_deg: float) -> list[tuple[int, list[int], np.ndarray, np.ndarray]]:
    """(band, IGP numbers 1…, their lat, lon) of the masked IGPs near (lat, lon)."""
    out = []
    for band in range(9):
        la, lo = band_igps(band)
        lo_w = np.mod(lo - lon_deg + 180.0, 360.0) - 180.0
        sel = (np.abs(la - lat_deg) <= 20) & (np.abs(lo_w) <= 25) & (np.abs(la) <= 55)
        if sel.any():
            out.append((band, (np.flatnonzero(sel) + 1).tolist(), la[sel], lo[sel]))
    return out


class _Truth:
    """Truth errors interpolated in time (held at the ends)."""

    def __init__(self, e: SatErrors) -> None:
        self.e = e

    def at(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        tt = self.e.t
        i = int(np.clip(np.searchsorted(tt, t), 1, tt.size - 1)) if tt.size > 1 else 0
        w = 0.0 if tt.size < 2 else float(np.clip((t - tt[i - 1]) / (tt[i] - tt[i - 1]), 0.0, 1.0))
        j = max(i - 1, 0)

        def lerp(a: FloatArray) -> FloatArray:
            return np.asarray(a[j] + w * (a[i] - a[j]), dtype=float)

        return lerp(self.e.sis_m), lerp(self.e.orbit_m), lerp(self.e.clock_m)

    def rates(self) -> tuple[FloatArray, FloatArray]:
        tt = self.e.t
        span = max(float(tt[-1] - tt[0]), 1.0)
        return (self.e.orbit_m[-1] - self.e.orbit_m[0]) / span, (self.e.clock_m[-1] - self.e.clock_m[0]) / span


def _ltc(truth: _Truth, slot: int, k: int, iode: int, t: float) -> enc.LongTerm:
    """Velocity-code-1 long-term correction of GPS satellite index ``k`` at t₀ ≈ t."""
    t0 = 16.0 * round(t / 16.0)
    _, orbit, clock = truth.at(t0)
    v, cv = truth.rates()
    o, r = orbit[k], v[k]
    return enc.LongTerm(
        slot, iode, float(o[0]), float(o[1]), float(o[2]), float(clock[k] / C_MPS),
        float(r[0]), float(r[1]), float(r[2]), float(cv[k] / C_MPS), t0_s=float(np.mod(t0, 86_400.0)),
    )  # fmt: skip


def sbas_stream(
    sim: Simulated,
    seed: int,
    *,
    geo: int = 137,
    lead_s: float = 0.0,
    t0_gps: float | None = None,
    fast_sigma_m: float = 0.25,
) -> pd.DataFrame:
    """``gnss_sbas`` rows for ``sim`` (module docstring); ``t`` counts from ``t0_gps`` (default:
    the first epoch's GPS time)."""
    if sim.truth_errors is None:
        raise ValueError("the simulated run carries no truth errors")
    e = sim.truth_errors
    truth = _Truth(e)
    gps = [k for k, s in enumerate(e.sats) if str(s).startswith("G")]
    prns = [int(str(e.sats[k])[1:]) for k in gps]
    table = nav_table(sim.nav)
    lat, lon, _ = ecef_to_geodetic(np.asarray(sim.truth[["x_m", "y_m", "z_m"]].to_numpy(float).mean(axis=0)))
    layout = _igp_layout(float(np.degrees(lat)), float(np.degrees(lon)))
    rng = np.random.default_rng([seed, 0x5BA5, 1])
    start = float(np.floor(e.t[0] - lead_s))
    seconds = np.arange(start, float(np.ceil(e.t[-1])) + 1.0)
    n_gm = seconds.size
    a = np.exp(-1.0 / 120.0)
    gm = np.empty((n_gm, len(gps)))
    gm[0] = rng.standard_normal(len(gps))
    drive = rng.standard_normal((n_gm, len(gps))) * np.sqrt(1.0 - a * a)
    for i in range(1, n_gm):  # a recursion in time
        gm[i] = a * gm[i - 1] + drive[i]
    gm *= fast_sigma_m
    queue = _slow_queue(layout, len(gps))
    rows: list[tuple[float, int, str]] = []
    iodf = [0, 0, 0, 0]
    q_pos = 0
    for i, t_of in enumerate(seconds):
        phase = round(t_of - start) % 6
        pre = int(t_of) % 3
        if phase < 3:
            block = phase
            slots = list(range(13 * block, min(13 * block + 13, len(gps))))
            if not slots:
                continue
            iodf[block] = (iodf[block] + 1) % 3
            prc = _fast(truth, gps, slots, float(t_of)) + gm[i, slots]
            msg = enc.mt_fast(2 + block, iodf[block], IODP, prc.tolist(), [UDREI_SIM] * len(slots), pre)
        else:
            item = queue[q_pos % len(queue)]
            q_pos += 1
            msg = _slow(item, truth, table, gps, e.sats, prns, layout, iodf, float(t_of), e.iono_run_scale, pre)
        rows.append((float(t_of) + 1.125, geo, msg.hex().upper()))
    ref = float(e.t[0]) if t0_gps is None else t0_gps
    t_rx = np.array([r[0] for r in rows])
    return pd.DataFrame(
        {
            "t": t_rx - ref,
            "gnss_time_s": t_rx,
            "prn": np.array([r[1] for r in rows], dtype=np.int64),
            "msg_type": [int(bytes.fromhex(r[2])[1] >> 2) for r in rows],
            "message_hex": [r[2] for r in rows],
            "valid": 1,
        }
    )


def _iode(table: NavTable, sats: np.ndarray, ks: list[int], t: float) -> list[int]:
    """IODE of the ephemeris a user selects at t for satellites ``ks`` (−1: none)."""
    idx = select_ephemeris(table, np.asarray(sats)[ks], np.full(len(ks), t))
    iode = np.where(idx >= 0, table.field["IODE"][np.maximum(idx, 0)], -1)
    return [int(v) for v in iode]


def _fast(truth: _Truth, gps: list[int], slots: list[int], t: float) -> FloatArray:
    """PRC of mask slots (0-based) at t (module docstring; without the network error)."""
    sis, _, clock = truth.at(t)
    ks = [gps[s] for s in slots]
    out = np.zeros(len(ks))
    for n, k in enumerate(ks):
        lt = _ltc(truth, 1, k, 0, t)
        daf0 = enc.q(lt.daf0_s, 2.0**-31) * 2.0**-31
        daf1 = enc.q(lt.daf1_sps, 2.0**-39) * 2.0**-39
        dclk_ltc_m = C_MPS * (daf0 + daf1 * (t - 16.0 * round(t / 16.0)))
        out[n] = -sis[k] - (dclk_ltc_m - clock[k])
    return out


def _slow_queue(layout: list[tuple[int, list[int], np.ndarray, np.ndarray]], n_gps: int) -> list[tuple[str, int]]:
    q: list[tuple[str, int]] = [("mt1", 0), ("mt7", 0), ("mt10", 0)]
    q += [("mt18", b) for b in range(len(layout))]
    q += [("mt25", k) for k in range(0, n_gps, 2)]
    q.append(("mt6", 0))
    for b, (_, igps, _, _) in enumerate(layout):
        q += [("mt26", b * 100 + blk) for blk in range((len(igps) + 14) // 15)]
    return q


def _slow(
    item: tuple[str, int],
    truth: _Truth,
    table: NavTable,
    gps: list[int],
    sats: np.ndarray,
    prns: list[int],
    layout: list[tuple[int, list[int], np.ndarray, np.ndarray]],
    iodf: list[int],
    t: float,
    iono_scale: float,
    pre: int,
) -> bytes:
    kind, arg = item
    if kind == "mt1":
        return enc.mt1(prns, IODP, pre)
    if kind == "mt7":
        return enc.mt7(2, IODP, [AI_SIM] * len(gps), pre)
    if kind == "mt10":
        return enc.mt10(MT10_SIM, pre)
    if kind == "mt6":
        return enc.mt6(iodf, [UDREI_SIM] * len(gps), pre)
    if kind == "mt18":
        band, igps, _, _ = layout[arg]
        return enc.mt18(len(layout), band, IODI, igps, pre)
    if kind == "mt25":
        ks = [k for k in (arg, arg + 1) if k < len(gps)]
        iodes = _iode(table, sats, [gps[k] for k in ks], t)
        halves = [(True, [_ltc(truth, k + 1, gps[k], io, t)]) for k, io in zip(ks, iodes, strict=True) if io >= 0]
        while len(halves) < 2:
            halves.append((False, []))
        return enc.mt25(halves[0], halves[1], IODP, pre)
    band_i, blk = divmod(arg, 100)
    band, _, la, lo = layout[band_i]
    sl = slice(15 * blk, 15 * blk + 15)
    delay = klobuchar_vertical_m(la[sl], lo[sl], t) * iono_scale
    return enc.mt26(band, blk, [min(float(d), 63.75) for d in delay], _givei(delay), IODI, pre)
