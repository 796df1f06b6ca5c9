"""δUDRE, the location-specific factor of σ_UDRE in σ_flt (RTCA DO-229 §A.4.5.1), from MT 27 or 28.

σ_flt = σ_UDRE·δUDRE + ε (``clock_orbit``; RSS_UDRE = 1: √((σ_UDRE·δUDRE)² + ε²)). δUDRE = 1
where neither message is in force.

MT 28 (clock-ephemeris covariance, one or two satellites per message, time-out 240 s):
R the upper-triangular Cholesky factor with the broadcast integers E_ij scaled by
SF = 2^(scale exponent − 5) [m], C = RᵀR, and I = [ê, 1] with ê the unit vector from the user to
the satellite (ECEF): δUDRE = √(IᵀCI) + ε_c, ε_c = C_covariance·SF (MT 10; 0 without one). Its
slots resolve through the MT 1 mask of its IODP, like every per-satellite message.

MT 27 (service message, time-out 86 400 s): a set of ``n_messages`` messages of one IODS, each
with a priority code, δUDRE indicators inside and outside, and up to five regions; a region's
corners are 1 (lat₁, lon₁), 2 (lat₂, lon₂), 3 (lat₁, lon₂) and, for a square, 4 (lat₂, lon₁)
(a triangle has its right angle at corner 3). The set in force is the IODS of the latest MT 27;
of it the latest message of each number. A user inside (boundary included) one or more regions
takes the inside indicator of the highest-priority message that contains him (the smaller δUDRE
among equal priorities); outside all, the outside indicator of the highest-priority message
(the larger δUDRE among equal ones). With an incomplete set (fewer numbers received than
``n_messages``) a region of a missing message could hold the user, so the largest δUDRE the
received messages state applies (the safe side). Indicator → δUDRE: 1, 1.1, 1.25, 1.5, 2, 3,
4, 5, 6, 8, 10, 20, 30, 40, 50, 100. MT 28 takes precedence where both apply to a satellite.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import FloatArray, StrArray
from fieldlogs.gnss.sbas.clock_orbit import _latest, with_sat
from fieldlogs.gnss.sbas.messages import SbasMessages

#: δUDRE per MT 27 indicator 0–15.
DELTA_UDRE: Final = np.array([1.0, 1.1, 1.25, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 20.0, 30.0, 40.0, 50.0, 100.0])
TIMEOUT_MT27_S: Final = 86_400.0
TIMEOUT_MT28_S: Final = 240.0
_E = ("e11", "e22", "e33", "e44", "e12", "e13", "e14", "e23", "e24", "e34")


def in_region(lat: FloatArray, lon: FloatArray, r: pd.Series) -> np.ndarray:
    """Whether each (lat, lon) [deg] lies in the MT 27 region ``r`` (module docstring), boundary
    included; longitudes compared east of lon₁ modulo 360°."""
    lat1, lat2 = float(r["lat1"]), float(r["lat2"])
    span = float(np.mod(float(r["lon2"]) - float(r["lon1"]), 360.0))
    x = np.mod(np.asarray(lon, dtype=float) - float(r["lon1"]), 360.0)
    y = np.asarray(lat, dtype=float)
    lo_lat, hi_lat = min(lat1, lat2), max(lat1, lat2)
    box = (x <= span + 1e-9) & (y >= lo_lat - 1e-9) & (y <= hi_lat + 1e-9)
    if bool(r["square"]):
        return np.asarray(box, dtype=bool)
    # triangle: corners (0, lat1), (span, lat2), (span, lat1); the right angle at (span, lat1)
    u = x / span if span > 0 else np.zeros_like(x)  # 0 at lon1, 1 at lon2
    v = (y - lat1) / (lat2 - lat1) if lat2 != lat1 else np.zeros_like(y)  # 0 at lat1, 1 at lat2
    return np.asarray(box & (v <= u + 1e-9), dtype=bool)


@dataclass(frozen=True)
class DeltaUdre:
    """One GEO's MT 27 and MT 28 records (module docstring)."""

    service: pd.DataFrame
    covariance: pd.DataFrame
    mt10: pd.DataFrame

    @classmethod
    def build(cls, msg: SbasMessages) -> DeltaUdre:
        cov = with_sat(msg.covariance, msg.masks) if not msg.covariance.empty else msg.covariance
        return cls(msg.service, cov, msg.mt10)

    @property
    def empty(self) -> bool:
        return self.service.empty and self.covariance.empty

    def _mt28(self, sat: StrArray, t: FloatArray, los: FloatArray) -> FloatArray:
        """δUDRE of MT 28 per row (NaN where none is in force)."""
        n = t.size
        if self.covariance.empty:
            return np.full(n, np.nan)
        q = pd.DataFrame({"row": np.arange(n), "sat": np.asarray(sat, dtype=str), "t": t})
        c = _latest(q, self.covariance, ["sat"], ["t_rx", "scale_exponent", *_E], TIMEOUT_MT28_S)
        sf = 2.0 ** (c["scale_exponent"].to_numpy(dtype=float) - 5.0)
        e = {k: c[k].to_numpy(dtype=float) * sf for k in _E}
        z = np.zeros(n)
        r = np.stack(
            [
                np.stack([e["e11"], e["e12"], e["e13"], e["e14"]], axis=-1),
                np.stack([z, e["e22"], e["e23"], e["e24"]], axis=-1),
                np.stack([z, z, e["e33"], e["e34"]], axis=-1),
                np.stack([z, z, z, e["e44"]], axis=-1),
            ],
            axis=1,
        )  # (n, 4, 4), rows of R
        i_vec = np.concatenate([np.asarray(los, dtype=float).reshape(n, 3), np.ones((n, 1))], axis=1)
        ri = np.einsum("nij,nj->ni", r, i_vec)  # R·I, so IᵀCI = |R·I|²
        eps_c = np.zeros(n)
        if not self.mt10.empty:
            p = _latest(q.assign(_k=0), self.mt10.assign(_k=0), ["_k"], ["c_covariance"], 360.0)
            eps_c = np.nan_to_num(p["c_covariance"].to_numpy(dtype=float), nan=0.0) * sf
        return np.asarray(np.sqrt(np.sum(ri**2, axis=1)) + eps_c, dtype=float)

    def _mt27(self, t: FloatArray, lat: FloatArray, lon: FloatArray) -> FloatArray:
        """δUDRE of MT 27 per row (NaN where no set is in force)."""
        out = np.full(t.size, np.nan)
        if self.service.empty:
            return out
        s = self.service.sort_values("t_rx", kind="stable")
        heads = s.drop_duplicates("t_rx", keep="first")  # one row per message
        ht = heads["t_rx"].to_numpy(dtype=float)
        k = np.searchsorted(ht, t, side="right") - 1
        for j in np.unique(k[k >= 0]).tolist():  # the messages received so far decide
            rows = np.flatnonzero(k == j)
            rows = rows[t[rows] - ht[j] <= TIMEOUT_MT27_S]
            if not rows.size:
                continue
            iods = int(heads["iods"].iloc[j])
            got = heads.iloc[: j + 1]
            got = got[got["iods"] == iods].drop_duplicates("number", keep="last")
            inside = DELTA_UDRE[got["inside"].to_numpy(dtype=np.int64)]
            outside = DELTA_UDRE[got["outside"].to_numpy(dtype=np.int64)]
            if len(got) < int(got["n_messages"].iloc[-1]):
                out[rows] = max(float(inside.max()), float(outside.max()))
                continue
            prio = got["priority"].to_numpy(dtype=np.int64)
            # outside all regions: the highest priority's outside value (the larger on a tie)
            top = prio == prio.max()
            val = np.full(rows.size, float(outside[top].max()))
            best_p = np.full(rows.size, -1)
            for m, (_, msg) in enumerate(got.iterrows()):
                regs = s[(s["t_rx"] == msg["t_rx"]) & (s["region"] >= 0)]
                hit = np.zeros(rows.size, dtype=bool)
                for _, r in regs.iterrows():
                    hit |= in_region(lat[rows], lon[rows], r)
                better = hit & (prio[m] > best_p)
                same = hit & (prio[m] == best_p)
                val = np.where(better, inside[m], np.where(same, np.minimum(val, inside[m]), val))
                best_p = np.where(better, prio[m], best_p)
            out[rows] = val
        return out

    def factor(
        self, sat: StrArray, t: FloatArray, lat_deg: FloatArray, lon_deg: FloatArray, los: FloatArray
    ) -> FloatArray:
        """δUDRE per row (module docstring): MT 28, else MT 27, else 1."""
        tt = np.asarray(t, dtype=float)
        d28 = self._mt28(sat, tt, los)
        d27 = self._mt27(tt, np.asarray(lat_deg, dtype=float), np.asarray(lon_deg, dtype=float))
        return np.where(np.isfinite(d28), d28, np.where(np.isfinite(d27), d27, 1.0))
