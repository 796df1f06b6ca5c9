"""The corrections seam: D-GPS range corrections, and the per-row form SBAS/MSAS corrections take.

A corrections frame has one row per satellite and time of applicability:

* ``gnss_time_s``, ``sat``;
* ``prc_m`` — fast pseudorange correction, added to the measured pseudorange (RTCA DO-229
  Appendix A: PR_corrected = PR + FC + RRC·(t − t_of)), with ``rrc_mps`` its range-rate correction;
* ``dx_m``, ``dy_m``, ``dz_m``, ``dclock_s`` — long-term correction of the broadcast satellite
  position (ECEF) and clock (DO-229 Appendix A), added to the broadcast values;
* ``sigma_m`` — 1σ of the corrected range (σ_flt from the UDRE, or the D-GPS residual);
* ``usable`` — False where the augmentation says "do not use" (UDREI 15; the paper's MSAS
  screening discards such satellites);
* ``covers_atmosphere`` — True for D-GPS corrections, whose PRC also removes the ionospheric
  and tropospheric delays at the reference station: the models are then not applied. SBAS
  corrections leave the ionosphere to their grid (``fieldlogs.gnss.sbas.grid``).

A correction applies to observations at t with t_of ≤ t ≤ t_of + ``max_age_s`` (the
latest such row). SBAS messages are decoded and matched by :mod:`fieldlogs.gnss.sbas` (its own
time-outs, IODE matching and σ_flt), which returns the same :class:`RowCorrections`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import BoolArray, FloatArray, StrArray
from schemas.errors import InputError

CORR_COLUMNS: Final = (
    "gnss_time_s",
    "sat",
    "prc_m",
    "rrc_mps",
    "dx_m",
    "dy_m",
    "dz_m",
    "dclock_s",
    "sigma_m",
    "usable",
    "covers_atmosphere",
)


class CorrectionsError(InputError):
    """A corrections frame without a required column."""


@dataclass(frozen=True)
class RowCorrections:
    """Corrections matched to observation rows (zeros and NaN σ where none applies)."""

    present: BoolArray
    prc_m: FloatArray
    dpos_m: FloatArray
    dclock_s: FloatArray
    sigma_m: FloatArray
    usable: BoolArray
    covers_atmosphere: BoolArray
    udre_sigma_m: FloatArray | None = None
    """SBAS: σ_UDRE of each corrected row (NaN elsewhere), for δUDRE (``sbas.delta_udre``)."""
    udre_rss: BoolArray | None = None
    """SBAS: σ_flt of the row is a root sum of squares (MT 10 RSS_UDRE = 1)."""


def no_corrections(n: int) -> RowCorrections:
    """The neutral element: nothing applies."""
    z = np.zeros(n)
    f = np.zeros(n, dtype=bool)
    return RowCorrections(f, z, np.zeros((n, 3)), z.copy(), np.full(n, np.nan), np.ones(n, dtype=bool), f.copy())


def match_corrections(
    corrections: pd.DataFrame | None, sat: StrArray, t: FloatArray, max_age_s: float = 30.0
) -> RowCorrections:
    """The latest correction of each row's satellite not older than ``max_age_s``."""
    n = int(np.asarray(t).size)
    if corrections is None or corrections.empty:
        return no_corrections(n)
    need = ("gnss_time_s", "sat", "prc_m")
    missing = [c for c in need if c not in corrections.columns]
    if missing:
        raise CorrectionsError("missing column", path="corrections frame", column=missing[0])
    c = corrections.copy()
    for col, default in (("rrc_mps", 0.0), ("dx_m", 0.0), ("dy_m", 0.0), ("dz_m", 0.0), ("dclock_s", 0.0)):
        c[col] = c[col].fillna(default) if col in c.columns else default
    c["sigma_m"] = c["sigma_m"] if "sigma_m" in c.columns else np.nan
    c["usable"] = c["usable"].astype(bool) if "usable" in c.columns else True
    c["covers_atmosphere"] = c["covers_atmosphere"].astype(bool) if "covers_atmosphere" in c.columns else False
    c = c.rename(columns={"gnss_time_s": "t_of"}).sort_values("t_of")
    q = pd.DataFrame({"row": np.arange(n), "sat": np.asarray(sat, dtype=str), "t": np.asarray(t, dtype=float)})
    q = q.sort_values("t")
    m = pd.merge_asof(
        q,
        c,
        left_on="t",
        right_on="t_of",
        by="sat",
        direction="backward",
        tolerance=max_age_s,  # type: ignore[arg-type]
    )  # float keys take a float tolerance (the stubs know only time-like ones)
    m = m.sort_values("row")
    present = m["t_of"].notna().to_numpy()
    dt = np.where(present, m["t"].to_numpy() - m["t_of"].to_numpy(), 0.0)
    prc = np.where(present, m["prc_m"].to_numpy(float) + m["rrc_mps"].to_numpy(float) * dt, 0.0)
    dpos = np.where(present[:, None], m[["dx_m", "dy_m", "dz_m"]].to_numpy(float), 0.0)
    return RowCorrections(
        present=present,
        prc_m=prc,
        dpos_m=dpos,
        dclock_s=np.where(present, m["dclock_s"].to_numpy(float), 0.0),
        sigma_m=np.where(present, m["sigma_m"].to_numpy(float), np.nan),
        usable=np.where(present, m["usable"].fillna(True).to_numpy(bool), True),
        covers_atmosphere=np.where(present, m["covers_atmosphere"].fillna(False).to_numpy(bool), False),
    )
