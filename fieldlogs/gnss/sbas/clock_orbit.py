"""SBAS fast and long-term corrections applied to observation rows (RTCA DO-229 §A.4.4, §A.4.5).

For an observation of satellite i at time t (the receiver's GPS time) with broadcast ephemeris
IODE, the corrections in force are the latest received before t (records whose PRN-mask slot
resolves through the MT 1 mask of their IODP, received before them):

* fast correction (§A.4.4.3): PRC(t) = PRC(t_of) + RRC·(t − t_of), RRC = (PRC(t_of) −
  PRC(t_of,prev))/(t_of − t_of,prev) from the previous correction of the satellite when that
  one is within the time-out, else 0; not applied when t − t_of exceeds the user time-out
  I_fc of the satellite's a_i (MT 7, Table A-8), without a current MT 7, or when the UDREI in
  force (the newer of the fast correction's and MT 6's with a matching IODF, or IODF 3) is older
  than 18 s (Table A-25);
* long-term correction (§A.4.4.7): only with the IODE of the ephemeris in use; velocity code 1:
  δr(t) = δr + δṙ·(t − t₀), δΔt(t) = δaf0 + δaf1·(t − t₀) (t₀ the nearest time of the given
  second of day); code 0: δr, δaf0; added to the broadcast satellite position and clock; not
  applied after 360 s. A satellite is corrected only with both (DO-229 §A.4.4.7: fast
  corrections alone are not a corrected range);
* "do not use" (UDREI 15) and "not monitored" (UDREI 14) rows are refused (``usable`` False,
  the observation flag ``augmentation_do_not_use``) whatever else is missing;
* MT 0 voids everything the GEO sent before it.

Error model (§A.4.5.1): σ²_flt = (σ_UDRE·δUDRE + ε_fc + ε_rrc + ε_ltc + ε_er)² (or the sum of
squares when MT 10's RSS_UDRE = 1), δUDRE = 1 here — the location-specific δUDRE of MT 27/28
needs the user's position and line of sight, so ``delta_udre`` scales σ_UDRE once the geometry
is known (``observables.apply_geometry``) —, ε_fc = a(t − t_u +
t_lat)²/2 with t_u the time of applicability of the UDREI, ε_rrc = (a·I_fc/4 + B_rrc/Δt)(t − t_of)
for successive IODFs and (a·|Δt − I_fc/2|/2 + B_rrc/Δt)(t − t_of) where either is 3 (0 with
a = 0 or no RRC), ε_ltc = C_ltc_v0·⌊(t − t_ltc)/I_ltc_v0⌋ (code 0) or 0 inside [t₀, t₀ + I_ltc_v1]
and C_ltc_lsb + C_ltc_v1·max(0, t₀ − t, t − t₀ − I_ltc_v1) outside (code 1), ε_er = 0 (timed-out
corrections are not applied); without MT 10, σ_flt = σ_UDRE·δUDRE + 8 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import FloatArray, StrArray
from fieldlogs.gnss.corrections import RowCorrections
from fieldlogs.gnss.sbas.decode import MT10_FIELDS
from fieldlogs.gnss.sbas.messages import SbasMessages
from fieldlogs.gnss.sbas_tables import (
    FC_DEGRADATION_MPS2,
    FC_TIMEOUT_S,
    NO_MT10_DEGRADATION_M,
    SIGMA2_UDRE_M2,
    TIMEOUT_S,
    UDREI_NOT_MONITORED,
    mask_slot_sat,
)

DAY_S = 86_400.0
MT10_NAMES = [name for name, _, _ in MT10_FIELDS]


def with_sat(df: pd.DataFrame, masks: pd.DataFrame, by_iodp: bool = True) -> pd.DataFrame:
    """``df`` rows with ``sat`` from the mask in force at their reception (module docstring);
    rows without one dropped."""
    if df.empty or masks.empty:
        return df.iloc[0:0].assign(sat=pd.Series(dtype=str))
    m = masks.assign(sat=mask_slot_sat(masks["prn"].to_numpy()), t_mask=masks["t_rx"])
    by = ["iodp", "slot"] if by_iodp else ["slot"]
    m = m[[*by, "t_rx", "t_mask", "sat"]].sort_values("t_rx")
    out = pd.merge_asof(
        df.sort_values("t_rx"),
        m,
        on="t_rx",
        by=by,
        direction="backward",
        tolerance=TIMEOUT_S["mask"],  # type: ignore[arg-type]
    )  # float keys take a float tolerance (the stubs know only time-like ones)
    out = out[out["sat"].notna() & (out["sat"] != "")]
    return pd.DataFrame(out.drop(columns="t_mask").reset_index(drop=True))


def _latest(q: pd.DataFrame, table: pd.DataFrame, by: list[str], cols: list[str], max_age: float) -> pd.DataFrame:
    """For each query row (columns ``row``, ``t`` and ``by``), the latest ``table`` row received
    (``t_rx``) at or before t and at most ``max_age`` old: its ``cols`` (NaN where none)."""
    if table.empty:
        return pd.DataFrame({c: np.full(len(q), np.nan) for c in cols}, index=q["row"].to_numpy())
    tb = table[[*by, *cols]].assign(_t=table["t_rx"].to_numpy(dtype=float)).sort_values("_t")
    m = pd.merge_asof(
        q.sort_values("t"),
        tb,
        left_on="t",
        right_on="_t",
        by=by,
        direction="backward",
        tolerance=max_age,  # type: ignore[arg-type]
    )
    return pd.DataFrame(m.set_index("row").sort_index()[cols])


@dataclass(frozen=True)
class ClockOrbitTables:
    """Decoded fast, integrity, degradation and long-term records with satellites resolved."""

    fast: pd.DataFrame
    integrity: pd.DataFrame
    degradation: pd.DataFrame
    long_term: pd.DataFrame
    mt10: pd.DataFrame
    mt0_t: FloatArray

    @classmethod
    def build(cls, msg: SbasMessages) -> ClockOrbitTables:
        fast = with_sat(msg.fast, msg.masks)
        if not fast.empty:
            fast = fast.sort_values(["sat", "t_rx"], kind="stable").reset_index(drop=True)
            g = fast.groupby("sat")
            fast["prev_prc_m"] = g["prc_m"].shift()
            fast["prev_t_of"] = g["t_of"].shift()
            fast["prev_iodf"] = g["iodf"].shift()
        lt = with_sat(msg.long_term, msg.masks)
        if not lt.empty:
            lt = lt.assign(t_ltc=np.floor(lt["t_rx"].to_numpy(dtype=float) - 1.1))
        mt0 = np.sort(msg.mt0["t_rx"].to_numpy(dtype=float)) if not msg.mt0.empty else np.zeros(0)
        return cls(
            fast,
            with_sat(msg.integrity, msg.masks, by_iodp=False),
            with_sat(msg.degradation, msg.masks),
            lt,
            msg.mt10,
            mt0,
        )

    def rows(self, sat: StrArray, t: FloatArray, iode: FloatArray) -> tuple[RowCorrections, dict[str, int]]:
        """Corrections of observation rows (module docstring) and counts of rows by outcome."""
        n = int(np.asarray(t).size)
        q = pd.DataFrame({"row": np.arange(n), "sat": np.asarray(sat, dtype=str), "t": np.asarray(t, dtype=float)})
        q["iode"] = np.nan_to_num(np.asarray(iode, dtype=float), nan=-1.0).astype(np.int64)
        fc = _latest(q, self.fast, ["sat"], _FAST_COLS, max(FC_TIMEOUT_S))
        mt6 = _latest(q, self.integrity, ["sat"], ["t_of", "udrei", "iodf", "t_rx"], TIMEOUT_S["udrei"])
        dg = _latest(q, self.degradation, ["sat"], ["ai", "t_lat_s", "t_rx"], TIMEOUT_S["degradation"])
        lt = _latest(q, self.long_term, ["sat", "iode"], _LT_COLS, TIMEOUT_S["long_term"])
        mt10 = self.mt10.assign(_k=0) if not self.mt10.empty else self.mt10
        p10 = _latest(q.assign(_k=0), mt10, ["_k"], ["t_rx", *MT10_NAMES], TIMEOUT_S["degradation"])
        tt = q["t"].to_numpy(dtype=float)
        void = _mt0_before(self.mt0_t, tt)
        return _combine(tt, fc, mt6, dg, lt, p10, void)


_FAST_COLS = ["t_rx", "t_of", "prc_m", "udrei", "iodf", "prev_prc_m", "prev_t_of", "prev_iodf"]
_LT_COLS = [
    "t_rx", "t_ltc", "velocity", "dx_m", "dy_m", "dz_m", "daf0_s", "ddx_mps", "ddy_mps", "ddz_mps", "daf1_sps",
    "t0_sod_s",
]  # fmt: skip


def _mt0_before(mt0_t: FloatArray, t: FloatArray) -> FloatArray:
    """Reception time of the latest MT 0 at or before each t (−inf: none)."""
    if mt0_t.size == 0:
        return np.full(t.shape, -np.inf)
    i = np.searchsorted(mt0_t, t, side="right") - 1
    return np.where(i >= 0, mt0_t[np.maximum(i, 0)], -np.inf)


def _v(df: pd.DataFrame, c: str) -> FloatArray:
    return df[c].to_numpy(dtype=float) if c in df.columns else np.full(len(df), np.nan)


def _udrei(t: FloatArray, fc: pd.DataFrame, mt6: pd.DataFrame) -> tuple[FloatArray, FloatArray]:
    """UDREI in force and its time of applicability t_u: the newer of the fast correction's and
    MT 6's (when MT 6's IODF matches the fast correction's or is 3)."""
    ud_fc, tu_fc = _v(fc, "udrei"), _v(fc, "t_of")
    ud6, tu6, iodf6 = _v(mt6, "udrei"), _v(mt6, "t_of"), _v(mt6, "iodf")
    match = np.isfinite(ud6) & ((iodf6 == _v(fc, "iodf")) | (iodf6 == 3))
    take6 = match & (~np.isfinite(tu_fc) | (tu6 > tu_fc))
    ud = np.where(take6, ud6, ud_fc)
    tu = np.where(take6, tu6, tu_fc)
    fresh = np.isfinite(tu) & (t - tu <= TIMEOUT_S["udrei"])
    return np.where(fresh, ud, np.nan), tu


def _long_term(t: FloatArray, lt: pd.DataFrame) -> tuple[FloatArray, FloatArray, FloatArray]:
    """δr(t) (n, 3), δΔt(t) [s] and t₀ as continuous time (NaN for code 0)."""
    vel = _v(lt, "velocity") == 1.0
    sod = _v(lt, "t0_sod_s")
    day0 = np.floor(t / DAY_S) * DAY_S
    t0 = day0 + sod
    t0 = np.where(t0 - t > DAY_S / 2, t0 - DAY_S, np.where(t - t0 > DAY_S / 2, t0 + DAY_S, t0))
    dt = np.where(vel, t - t0, 0.0)
    dr = np.stack([_v(lt, c) + np.where(vel, _v(lt, r), 0.0) * dt for c, r in
                   (("dx_m", "ddx_mps"), ("dy_m", "ddy_mps"), ("dz_m", "ddz_mps"))], axis=-1)  # fmt: skip
    dclk = _v(lt, "daf0_s") + np.where(vel, _v(lt, "daf1_sps"), 0.0) * dt
    return dr, dclk, np.where(vel, t0, np.nan)


def _eps_ltc(t: FloatArray, lt: pd.DataFrame, t0: FloatArray, p10: pd.DataFrame) -> FloatArray:
    vel = _v(lt, "velocity") == 1.0
    i_v0 = _v(p10, "i_ltc_v0")
    steps = np.where(i_v0 > 0, np.floor((t - _v(lt, "t_ltc")) / np.where(i_v0 > 0, i_v0, 1.0)), 0.0)
    code0 = _v(p10, "c_ltc_v0") * steps
    i_v1 = _v(p10, "i_ltc_v1")
    inside = (t >= t0) & (t <= t0 + i_v1)
    outside = _v(p10, "c_ltc_lsb") + _v(p10, "c_ltc_v1") * np.maximum.reduce([np.zeros_like(t), t0 - t, t - t0 - i_v1])
    return np.where(vel, np.where(inside, 0.0, outside), code0)


def _eps_rrc(t: FloatArray, fc: pd.DataFrame, a: FloatArray, i_fc: FloatArray, p10: pd.DataFrame) -> FloatArray:
    d_t = _v(fc, "t_of") - _v(fc, "prev_t_of")
    iodf, prev = _v(fc, "iodf"), _v(fc, "prev_iodf")
    normal = (iodf != 3) & (prev != 3) & (np.mod(iodf - prev, 3) == 1)
    b_rrc = np.nan_to_num(_v(p10, "b_rrc"), nan=0.0)
    dts = np.where(d_t > 0, d_t, 1.0)
    rate = np.where(normal, a * i_fc / 4.0, a * np.abs(d_t - i_fc / 2.0) / 2.0) + b_rrc / dts
    has_rrc = np.isfinite(d_t) & (d_t > 0) & (d_t <= i_fc)
    return np.where(has_rrc & (a > 0), rate * (t - _v(fc, "t_of")), 0.0)


def _combine(
    t: FloatArray,
    fc: pd.DataFrame,
    mt6: pd.DataFrame,
    dg: pd.DataFrame,
    lt: pd.DataFrame,
    p10: pd.DataFrame,
    void: FloatArray,
) -> tuple[RowCorrections, dict[str, int]]:
    """The per-row corrections, σ_flt and outcome counts (module docstring)."""
    n = t.size
    udrei, t_u = _udrei(t, fc, mt6)
    ai = np.nan_to_num(_v(dg, "ai"), nan=0.0).astype(np.int64)
    a, i_fc = FC_DEGRADATION_MPS2[ai], FC_TIMEOUT_S[ai]
    has_fc = np.isfinite(_v(fc, "t_of")) & (t - _v(fc, "t_of") <= i_fc) & (_v(fc, "t_rx") > void)
    has_dg = np.isfinite(_v(dg, "t_rx")) & (_v(dg, "t_rx") > void)
    has_lt = np.isfinite(_v(lt, "t_rx")) & (_v(lt, "t_rx") > void)
    refused = np.isfinite(udrei) & (udrei >= UDREI_NOT_MONITORED)
    present = has_fc & has_dg & has_lt & np.isfinite(udrei) & ~refused
    d_t = _v(fc, "t_of") - _v(fc, "prev_t_of")
    rrc_ok = np.isfinite(d_t) & (d_t > 0) & (d_t <= i_fc)
    rrc = np.where(rrc_ok, (_v(fc, "prc_m") - _v(fc, "prev_prc_m")) / np.where(rrc_ok, d_t, 1.0), 0.0)
    prc = _v(fc, "prc_m") + rrc * (t - _v(fc, "t_of"))
    dr, dclk, t0 = _long_term(t, lt)
    sig_udre = np.sqrt(SIGMA2_UDRE_M2[np.clip(np.nan_to_num(udrei, nan=0.0).astype(np.int64), 0, 15)])
    eps_fc = a * (t - t_u + np.nan_to_num(_v(dg, "t_lat_s"), nan=0.0)) ** 2 / 2.0
    eps_rrc = _eps_rrc(t, fc, a, i_fc, p10)
    eps_ltc = np.nan_to_num(_eps_ltc(t, lt, t0, p10), nan=0.0)
    has10 = np.isfinite(_v(p10, "t_rx"))
    rss = _v(p10, "rss_udre") == 1.0
    lin = sig_udre + eps_fc + eps_rrc + eps_ltc
    root = np.sqrt(sig_udre**2 + eps_fc**2 + eps_rrc**2 + eps_ltc**2)
    sigma = np.where(has10, np.where(rss, root, lin), sig_udre + NO_MT10_DEGRADATION_M)
    out = RowCorrections(
        present=present,
        prc_m=np.where(present, prc, 0.0),
        dpos_m=np.where(present[:, None], dr, 0.0),
        dclock_s=np.where(present, dclk, 0.0),
        sigma_m=np.where(present, sigma, np.nan),
        usable=~refused,
        covers_atmosphere=np.zeros(n, dtype=bool),
        udre_sigma_m=np.where(present, sig_udre, np.nan),
        udre_rss=np.asarray(present & has10 & rss, dtype=bool),
    )
    counts = {
        "corrected": int(present.sum()),
        "refused_udrei": int(refused.sum()),
        "no_fast_correction": int((~refused & ~has_fc).sum()),
        "no_long_term": int((~refused & has_fc & ~has_lt).sum()),
        "no_degradation": int((~refused & has_fc & has_lt & ~has_dg).sum()),
        "udrei_timed_out": int((~refused & has_fc & has_lt & has_dg & ~np.isfinite(udrei)).sum()),
    }
    return out, counts
