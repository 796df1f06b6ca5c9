"""The SBAS ionospheric grid at a pierce point (RTCA DO-229 §A.4.4.9, §A.4.4.10).

Grid: each MT 26 block b of band B gives the vertical delays τ_v (0.125 m, code 511 "do not
use") and GIVEIs of the band's masked IGPs 15b + 1 … 15b + 15 in mask order, under the MT 18
mask with the same IODI received before it. An IGP is *available* at t when its latest delay
is at most 600 s old (Table A-25), not "do not use" and its GIVEI not 15 (not monitored).

Pierce point (§A.4.4.10.1), R_e = 6378.1363 km, h_I = 350 km, user at (φ_u, λ_u), satellite at
azimuth A and elevation E:
ψ_pp = π/2 − E − asin(R_e cos E/(R_e + h_I)); φ_pp = asin(sin φ_u cos ψ_pp + cos φ_u sin ψ_pp cos A);
λ_pp = λ_u + asin(sin ψ_pp sin A/cos φ_pp), or λ_u + π − asin(…) when the pierce point lies
beyond the pole (φ_u > 70° and tan ψ_pp cos A > tan(π/2 − φ_u), or φ_u < −70° and
−tan ψ_pp cos A > tan(π/2 + φ_u)). Obliquity F_pp = [1 − (R_e cos E/(R_e + h_I))²]^(−1/2).

Interpolation (§A.4.4.10.2–3): up to 60° of latitude, the 5° × 5° cell around the pierce point
if its four IGPs are available — x = (λ_pp − λ₁)/5°, y = (φ_pp − φ₁)/5° from its south-west corner, weights
(1 − x)(1 − y), x(1 − y), xy, (1 − x)y; with exactly three available and the pierce point inside
their triangle, the three-point form W = 1 − x' − y' at the right-angle corner and x', y' at its
neighbours along longitude and latitude (x', y' measured from that corner); else the same on
the 10° × 10° cell; between 60° and 75° (N or S) the same on the 5° (latitude) × 10°
(longitude) cell, x = (λ_pp − λ₁)/10°, y = (φ_pp − φ₁)/5° (the IGPs there are 10° apart in
longitude but for the 60° row of bands 9–10); else no SBAS ionosphere (the broadcast model
stays). Above 75° (the polar interpolation between the 85° IGPs 90° apart of §A.4.4.10.3) the
grid is not used: the broadcast model and its σ stay there. Delay
τ_pp = Σ Wₙ τ_v,n; slant delay on L1 F_pp·τ_pp, on another frequency × (f_L1/f)².
σ²_UIVE = Σ Wₙ σ²_ionogrid,n, σ²_ionogrid = (σ_GIVE + ε_iono)² (MT 10 RSS_iono = 0) or
σ²_GIVE + ε²_iono (1), ε_iono = C_iono_step⌊(t − t_iono)/I_iono⌋ + C_iono_ramp(t − t_iono), t_iono the
MT 26's time of applicability; ε_iono = 0 without MT 10. σ_UIRE = F_pp·σ_UIVE.
Only |φ_pp| ≤ 75° is used (``tables.GRID_MAX_LAT_DEG``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import F_L1_HZ, BoolArray, FloatArray
from fieldlogs.gnss.sbas.decode import MT10_FIELDS
from fieldlogs.gnss.sbas.messages import RECEPTION_DELAY_S, SbasMessages
from fieldlogs.gnss.sbas_tables import (
    GIVEI_NOT_MONITORED,
    GRID_MAX_LAT_DEG,
    GRID_WIDE_CELL_LAT_DEG,
    IGP_DO_NOT_USE,
    SIGMA2_GIVE_M2,
    TIMEOUT_S,
    band_igps,
    igp_key,
)

R_E_M = 6_378_136.3
H_I_M = 350_000.0


def pierce_point(
    lat_rad: FloatArray, lon_rad: FloatArray, az_rad: FloatArray, el_rad: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(φ_pp, λ_pp [rad], F_pp) of DO-229 §A.4.4.10.1 (module docstring)."""
    el = np.asarray(el_rad, dtype=float)
    az = np.asarray(az_rad, dtype=float)
    lat = np.asarray(lat_rad, dtype=float)
    c = R_E_M * np.cos(el) / (R_E_M + H_I_M)
    psi = np.pi / 2.0 - el - np.arcsin(c)
    lat_pp = np.arcsin(np.sin(lat) * np.cos(psi) + np.cos(lat) * np.sin(psi) * np.cos(az))
    arc = np.arcsin(np.sin(psi) * np.sin(az) / np.cos(lat_pp))
    over = ((lat > np.radians(70.0)) & (np.tan(psi) * np.cos(az) > np.tan(np.pi / 2.0 - lat))) | (
        (lat < -np.radians(70.0)) & (-np.tan(psi) * np.cos(az) > np.tan(np.pi / 2.0 + lat))
    )  # the pierce point is beyond the pole
    lon_pp = np.asarray(lon_rad, dtype=float) + np.where(over, np.pi - arc, arc)
    return lat_pp, lon_pp, 1.0 / np.sqrt(1.0 - c * c)


def _grid_records(msg: SbasMessages) -> pd.DataFrame:
    """One row per IGP delay received: key, t_rx, t_iono, delay_m, sigma2_give, available."""
    if msg.iono.empty or msg.igp_mask.empty:
        return pd.DataFrame(columns=["key", "t_rx", "t_iono", "delay_m", "sigma2", "ok"])
    mask = msg.igp_mask[["t_rx", "band", "iodi", "order", "igp"]].sort_values("t_rx")
    m = pd.merge_asof(
        msg.iono.sort_values("t_rx"), mask, on="t_rx", by=["band", "iodi", "order"], direction="backward",
        tolerance=TIMEOUT_S["igp_mask"],  # type: ignore[arg-type]
    )  # fmt: skip
    m = m[m["igp"].notna()].reset_index(drop=True)
    lat = np.zeros(len(m), dtype=np.int64)
    lon = np.zeros(len(m), dtype=np.int64)
    ok_band = np.zeros(len(m), dtype=bool)
    for b in np.unique(m["band"].to_numpy()):
        la, lo = band_igps(int(b))
        sel = (m["band"] == b).to_numpy() & (m["igp"].to_numpy() <= la.size)
        j = m.loc[sel, "igp"].to_numpy(dtype=np.int64) - 1
        lat[sel], lon[sel], ok_band[sel] = la[j], lo[j], True
    code = m["delay_code"].to_numpy(dtype=np.int64)
    givei = m["givei"].to_numpy(dtype=np.int64)
    ok = ok_band & (code != IGP_DO_NOT_USE) & (givei != GIVEI_NOT_MONITORED)
    return pd.DataFrame(
        {
            "key": igp_key(lat, lon),
            "t_rx": m["t_rx"].to_numpy(dtype=float),
            "t_iono": np.floor(m["t_rx"].to_numpy(dtype=float) - RECEPTION_DELAY_S),
            "delay_m": code * 0.125,
            "sigma2": SIGMA2_GIVE_M2[givei],
            "ok": ok,
        }
    )[ok_band]


@dataclass(frozen=True)
class IonoGrid:
    """IGP delay records of one GEO and its MT 10 (module docstring)."""

    records: pd.DataFrame
    mt10: pd.DataFrame

    @classmethod
    def build(cls, msg: SbasMessages) -> IonoGrid:
        return cls(_grid_records(msg), msg.mt10)

    def _lookup(self, key: np.ndarray, t: FloatArray) -> tuple[BoolArray, FloatArray, FloatArray, FloatArray]:
        """Latest record of each (IGP key, t): available, delay, σ²_GIVE, t_iono."""
        n = key.size
        if self.records.empty or n == 0:
            z = np.full(n, np.nan)
            return np.zeros(n, dtype=bool), z, z.copy(), z.copy()
        q = pd.DataFrame({"row": np.arange(n), "key": key.astype(np.int64), "t": t})
        r = self.records.rename(columns={"t_rx": "_t"}).sort_values("_t")
        m = pd.merge_asof(
            q.sort_values("t"), r, left_on="t", right_on="_t", by="key", direction="backward",
            tolerance=TIMEOUT_S["iono"],  # type: ignore[arg-type]
        )  # fmt: skip
        m = m.set_index("row").sort_index()
        ok = m["ok"].fillna(False).to_numpy(dtype=bool)
        return ok, m["delay_m"].to_numpy(float), m["sigma2"].to_numpy(float), m["t_iono"].to_numpy(float)

    def _eps(self, t: FloatArray, t_iono: FloatArray) -> tuple[FloatArray, bool]:
        """ε_iono per corner and whether MT 10 asks for RSS (module docstring)."""
        if self.mt10.empty:
            return np.zeros_like(t), False
        p = self.mt10.sort_values("t_rx")
        i = np.searchsorted(p["t_rx"].to_numpy(dtype=float), t, side="right") - 1
        fresh = (i >= 0) & (t - p["t_rx"].to_numpy(dtype=float)[np.maximum(i, 0)] <= TIMEOUT_S["degradation"])
        cols = {name: p[name].to_numpy(dtype=float)[np.maximum(i, 0)] for name, _, _ in MT10_FIELDS}
        i_io = cols["i_iono"]
        steps = np.where(i_io > 0, np.floor((t - t_iono) / np.where(i_io > 0, i_io, 1.0)), 0.0)
        eps = cols["c_iono_step"] * steps + cols["c_iono_ramp"] * (t - t_iono)
        return np.where(fresh, eps, 0.0), bool(np.any(fresh & (cols["rss_iono"] == 1.0)))

    def _cell(
        self, lat: FloatArray, lon: FloatArray, t: FloatArray, step: float, step_lon: float | None = None
    ) -> tuple[BoolArray, FloatArray, FloatArray]:
        """Interpolation on the step° (latitude) × step_lon° (longitude, default step) cell around
        each pierce point [deg] (module docstring)."""
        d_lon = step if step_lon is None else step_lon
        la0, lo0 = np.floor(lat / step) * step, np.floor(lon / d_lon) * d_lon
        x, y = (lon - lo0) / d_lon, (lat - la0) / step
        corners = ((0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0))  # SW, SE, NE, NW as (dx, dy)
        ok = np.zeros((lat.size, 4), dtype=bool)
        tau, s2 = np.zeros((lat.size, 4)), np.zeros((lat.size, 4))
        for k, (dx, dy) in enumerate(corners):
            key = igp_key(np.round(la0 + dy * step).astype(np.int64), np.round(lo0 + dx * d_lon).astype(np.int64))
            a, d, v, ti = self._lookup(key, t)
            eps, rss = self._eps(t, ti)
            sg = np.sqrt(np.nan_to_num(v, nan=0.0))
            ok[:, k], tau[:, k] = a, np.nan_to_num(d)
            s2[:, k] = sg**2 + eps**2 if rss else (sg + eps) ** 2
        w4 = np.stack([(1 - x) * (1 - y), x * (1 - y), x * y, (1 - x) * y], axis=1)
        n_ok = ok.sum(axis=1)
        w = np.where((n_ok == 4)[:, None], w4, 0.0)
        # three corners: the missing one m, the right angle at m + 2 (opposite), neighbours m + 1, m + 3
        miss = np.argmin(ok, axis=1)
        v_idx = (miss + 2) % 4
        xv = np.array([dx for dx, _ in corners])[v_idx]
        yv = np.array([dy for _, dy in corners])[v_idx]
        xp, yp = np.abs(x - xv), np.abs(y - yv)
        tri = (n_ok == 3) & (xp + yp <= 1.0)
        rows = np.flatnonzero(tri)
        lon_nb = np.where(np.isin(v_idx, (0, 3)), np.where(v_idx == 0, 1, 2), np.where(v_idx == 1, 0, 3))
        lat_nb = np.where(np.isin(v_idx, (0, 1)), np.where(v_idx == 0, 3, 2), np.where(v_idx == 2, 1, 0))
        w[rows] = 0.0
        w[rows, v_idx[rows]] = 1.0 - xp[rows] - yp[rows]
        w[rows, lon_nb[rows]] = xp[rows]
        w[rows, lat_nb[rows]] = yp[rows]
        used = (n_ok == 4) | tri
        return used, np.sum(w * tau, axis=1), np.sum(w * s2, axis=1)

    def slant(
        self,
        lat_rad: FloatArray,
        lon_rad: FloatArray,
        az_rad: FloatArray,
        el_rad: FloatArray,
        t: FloatArray,
        freq_hz: FloatArray,
    ) -> tuple[BoolArray, FloatArray, FloatArray]:
        """(covered, slant delay [m], σ_UIRE [m]) for inputs broadcast together (module docstring)."""
        shape = np.broadcast(np.asarray(el_rad), np.asarray(az_rad), np.asarray(lat_rad), np.asarray(t)).shape
        b = [np.broadcast_to(np.asarray(v, dtype=float), shape).ravel() for v in (lat_rad, lon_rad, az_rad, el_rad, t)]
        lat_pp, lon_pp, f_pp = pierce_point(b[0], b[1], b[2], b[3])
        lat_d = np.degrees(lat_pp)
        lon_d = np.mod(np.degrees(lon_pp) + 180.0, 360.0) - 180.0
        inside = np.abs(lat_d) <= GRID_MAX_LAT_DEG
        wide = np.abs(lat_d) > GRID_WIDE_CELL_LAT_DEG
        cov5, tau5, s5 = self._cell(lat_d, lon_d, b[4], 5.0)
        cov10, tau10, s10 = self._cell(lat_d, lon_d, b[4], 10.0)
        cov_w, tau_w, s_w = self._cell(lat_d, lon_d, b[4], 5.0, 10.0)
        cov5, cov10 = cov5 & ~wide, cov10 & ~wide
        cov_w = cov_w & wide
        cov = inside & (cov5 | cov10 | cov_w)
        tau = np.where(cov5, tau5, np.where(cov10, tau10, tau_w))
        s2 = np.where(cov5, s5, np.where(cov10, s10, s_w))
        scale = (F_L1_HZ / np.broadcast_to(np.asarray(freq_hz, dtype=float), shape).ravel()) ** 2
        delay = np.where(cov, f_pp * tau * scale, np.nan)
        sigma = np.where(cov, f_pp * np.sqrt(s2) * scale, np.nan)
        return cov.reshape(shape), delay.reshape(shape), sigma.reshape(shape)
