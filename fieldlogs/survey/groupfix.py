"""Places of the G balises on tracks off every line (a crossover), by dead reckoning from
the run's own earlier reference.

A G balise on a track with no line km (:mod:`fieldlogs.survey.groups`) has no neighbours on
a line to be placed between; but every run that reads it knows where it was just before: the
pipeline's position on that track at the last cycle *before the group's first telegram* of
the pass — carried there from the previous absolute fix on the path, over the switch toe and
onto the track as entered (its place ``pos_m`` from the track's begin), with the margin the
pipeline holds for it (the reference's uncertainty plus its growth since). The group's own
correction (its first balise fixes the position, the second would then repeat the DB's
spacing) comes after that cycle and never enters. The read's place on the track is

    p = pos_ref + σ·λ·(d_read − d_ref) + σ·cab·x_r

(σ = ±1 pos per metre of travel over the run's stretch on the track, λ the run's wheel scale
— the travel is 1/λ times the true distance —, d the travel, x_r the reader's offset ahead
of the reference point, :mod:`fieldlogs.pipeline.geometry`), bounded by

    m = margin_ref + ``margin.distance_pct`` % · (d_read − d_ref)

— the pipeline's margin grown as it grows over the dead-reckoned stretch. A read whose
reference cycle is not on the balise's track (the position was still on the track before,
or ambiguous) gives no place. The placements are made per run
(:func:`fieldlogs.survey.groups.run_placements`), combined here.

Per balise over its placements (n): the mean place p̄, its km through the track's
``track_points`` (:func:`fieldlogs.survey.groups.track_km`) as ``km_surveyed_m``, the
residual DB km − that km, and the interval ± (t₀.₉₇₅(n − 1)·s/√n + m̄) — the passes'
spread *plus* the mean of their margins: the reference's uncertainty is not averaged out
(one run's error of the previous fix is shared by its reads). Status (as the other balises):
**ok** when the interval lies within ±``ok_tolerance_m``, **moved** when |residual| ≥
``moved_min_m`` and the interval excludes 0, else **unverified** (fewer than
``min_passes`` placements, or inconclusive: a crossover's reference margin is usually
metres).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from fieldlogs.survey.balises import MOVED, OK, UNVERIFIED, t_quantile
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.groups import track_km

FloatArray = npt.NDArray[np.float64]
FIX_COLUMNS = ("balise_id", "n_estimates", "km_surveyed_m", "residual_m", "ci95_m", "spread_m", "margin_m")


def group_fixes(
    placements: Sequence[pd.DataFrame], scale: FloatArray, network: Network, places: pd.DataFrame
) -> pd.DataFrame:
    """Per balise over every run's placements (``placements[r]`` of run r, wheel scale
    ``scale[r]``): :data:`FIX_COLUMNS` (module docstring; ``ci95_m`` holds the spread's
    interval plus the mean margin)."""
    parts = [
        p.assign(place=p["pos_ref_m"] + (scale[r] if np.isfinite(scale[r]) else 1.0) * p["travel_m"] + p["reader_m"])
        for r, p in enumerate(placements)
        if len(p)
    ]
    if not parts:
        return pd.DataFrame(columns=list(FIX_COLUMNS))
    allp = pd.concat(parts, ignore_index=True)
    agg = allp.groupby("balise_id").agg(
        n=("place", "size"), mean=("place", "mean"), sd=("place", "std"), margin=("margin_m", "mean")
    )
    km_db = dict(zip(network.balises["balise_id"].astype(str), network.balises["km_actual_m"], strict=True))
    tracks = dict(zip(places["balise_id"], places["track_id"], strict=True))
    rows = []
    for bid, a in agg.iterrows():
        k, p = track_km(network.track_points, str(tracks[bid]))
        order = np.argsort(p)
        km = float(np.interp(a["mean"], p[order], k[order])) if k.size >= 2 else float("nan")
        n = int(a["n"])
        stat = float(t_quantile(n - 1)) * float(a["sd"]) / np.sqrt(n) if n >= 2 else float("nan")
        resid = float(km_db[str(bid)]) - km
        rows.append((str(bid), n, km, resid, stat + float(a["margin"]), float(a["sd"]), float(a["margin"])))
    return pd.DataFrame(rows, columns=list(FIX_COLUMNS))


def fix_status(fix: pd.Series, cfg: SurveyConfig) -> tuple[str, str]:
    """Status and reason of one dead-reckoned G balise (module docstring)."""
    n, res, half, m = int(fix["n_estimates"]), float(fix["residual_m"]), float(fix["ci95_m"]), float(fix["margin_m"])
    where = f"placed by dead reckoning from the run's earlier position ({n} passes, reference margin {m:.2f} m)"
    if n < cfg.min_passes or not np.isfinite(half):
        return UNVERIFIED, f"{where}: too few passes ({n} of {cfg.min_passes})"
    if abs(res) + half <= cfg.ok_tolerance_m:
        return OK, where
    if abs(res) >= cfg.moved_min_m and abs(res) > half:
        return MOVED, f"{where}: residual {res:+.2f} m ± {half:.2f} m"
    return UNVERIFIED, f"{where}: inconclusive, residual {res:+.2f} m ± {half:.2f} m"
