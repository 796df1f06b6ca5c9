"""Position-correction statistics — one definition for ``run``, ``audit`` and ``report``.

A correction's position-correction percentage [S003 §4.5, §5.2] is

    pct = |correction amount| / distance travelled since the previous correction × 100,

with correction amount = computed km − DB km. The papers report it for **balise
corrections** (mean 0.29 % Tohoku line, 0.37 % Kawagoe line, target 0.5 %), and that is
what ``n_corrections``, ``mean_correction_pct`` … mean everywhere in the suite. A
feature-point correction often follows a balise within a few hundred metres, which makes
its percentage meaningless as a wheel figure; the statistics over *all* absolute
corrections (balise + feature) are reported beside it under the ``all`` name, never mixed
into the balise figures. The first correction after power-up has no previous correction
and so no percentage: it is counted but does not enter the mean.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
import pandas as pd

from fieldlogs.pipeline.config import TARGET_PCT
from schemas.enums import CORRECTION_EVENTS, EventType

#: Which corrections a statistic covers: ``balise`` (the papers' statistic) or ``all``.
Population = Literal["balise", "all"]
POPULATIONS: dict[Population, tuple[EventType, ...]] = {
    "balise": (EventType.BALISE_CORRECTION,),
    "all": CORRECTION_EVENTS,
}
#: Columns of :func:`correction_stats`, in the order reports show them.
STAT_COLUMNS = (
    "n_corrections",
    "mean_correction_pct",
    "median_correction_pct",
    "max_correction_pct",
    "share_above_target",
)


def correction_stats(
    events: pd.DataFrame,
    by: Sequence[str] = (),
    *,
    population: Population = "balise",
    target_pct: float = TARGET_PCT,
    index: pd.Index | None = None,
) -> pd.DataFrame:
    """Statistics of the correction events of ``population``, one row per ``by`` group.

    ``events`` needs ``type`` and ``correction_pct`` (and the ``by`` columns). Without
    ``by`` the result has one row. ``index`` (the groups' index) reindexes the result so that
    groups without corrections appear with ``n_corrections`` 0 and undefined (NaN) means.
    ``share_above_target`` is the share of corrections with a % above ``target_pct``.
    """
    keys = list(by)
    corr = events[events["type"].isin([str(t) for t in POPULATIONS[population]])]
    pct = pd.to_numeric(corr["correction_pct"], errors="coerce").astype(float)
    frame = corr[keys].assign(pct=pct.to_numpy(), above=(pct > target_pct).astype(float).to_numpy())
    frame.loc[~np.isfinite(frame["pct"].to_numpy()), "above"] = np.nan
    grouped = frame.groupby(keys, sort=True) if keys else frame.groupby(np.zeros(len(frame), dtype=int))
    out = pd.DataFrame(
        {
            "n_corrections": grouped.size(),
            "mean_correction_pct": grouped["pct"].mean(),
            "median_correction_pct": grouped["pct"].median(),
            "max_correction_pct": grouped["pct"].max(),
            "share_above_target": grouped["above"].mean(),
        }
    )
    if not keys:
        out = out.reindex([0])
    elif index is not None:
        out = out.reindex(index)
    out["n_corrections"] = out["n_corrections"].fillna(0).astype(int)
    return out[list(STAT_COLUMNS)]


def run_correction_stats(
    events: pd.DataFrame, *, population: Population = "balise", target_pct: float = TARGET_PCT
) -> dict[str, int | float | None]:
    """:func:`correction_stats` of one run as a dict (None where undefined)."""
    row = correction_stats(events, population=population, target_pct=target_pct).iloc[0]
    return {c: (int(row[c]) if c == "n_corrections" else _opt(row[c])) for c in STAT_COLUMNS}


def _opt(v: object) -> float | None:
    f = float(v)  # type: ignore[arg-type]
    return f if np.isfinite(f) else None
