"""Per-cycle positions and margins from the sequence of fixes (vectorised).

Between fixes the position is dead reckoning (:mod:`fieldlogs.pipeline.estimate`), so the
engine only records the fixes; every cycle's state, km and margin follow from the fix in
force — the same numbers a per-cycle loop would give, without a Python step per 100 ms.

Margin [S000 §4.3.2] (|position error| ≤ margin must hold on every claimed cycle):

    margin = u_fix + p·|d − d_ref| + (A(d) − A_ref)  [+ q·|d − d_uncertain| while uncertain]

u_fix the fix's own uncertainty (balise 1 m, feature ≥ 10 m, GPS 10 m), p =
``margin.distance_pct`` (2 %) of the travel since the fix's reference point, A the
odometry's cumulative slip-correction budget ½·Δa·T² per episode (eq. 13) with A_ref its
value at the reference point, and q = ``margin.uncertain_growth_pct`` (5 %) of the travel
since a fail-safe made the position uncertain. The paper's margin adds a fixed 20 m per
slip; here each slip adds its own eq. 13 budget instead (22.8 m for a 10 s correction,
less for shorter ones), which the accuracy bench shows to hold.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.geometry import VehicleGeometry
from fieldlogs.pipeline.types import Fix, FloatArray
from schemas.enums import FixSource, PositionState


def margin_m(fix: Fix, d: FloatArray | float, allowance: FloatArray | float, cfg: MarginConfig) -> FloatArray:
    """The margin of the module docstring for ``fix`` at travel ``d`` and slip budget ``allowance``."""
    d_a = np.asarray(d, dtype=float)
    m = fix.uncertainty_m + cfg.distance_pct / 100.0 * np.abs(d_a - fix.d_ref)
    m = m + np.maximum(np.asarray(allowance, dtype=float) - fix.allowance_ref_m, 0.0)
    if fix.uncertain_since_d is not None:
        m = m + cfg.uncertain_growth_pct / 100.0 * np.abs(d_a - fix.uncertain_since_d)
    return np.asarray(m, dtype=float)


def text_column(codes: npt.NDArray[np.uint8], values: dict[str, int]) -> npt.NDArray[np.object_]:
    """The object column whose cell i is the str of code ``codes[i]`` in ``values`` (str → code):
    every cell a reference to one of those few str objects. ``np.full(n, "text", dtype=object)``
    makes a new str per cell instead (the fill goes through a fixed-width unicode array), ≈ 60 B
    a cycle per column — 50 MB each for a day at 10 Hz, only to be read once into Arrow."""
    pool = np.empty(len(values), dtype=object)
    for text, code in values.items():
        pool[code] = text
    return np.take(pool, codes)


def positions_frame(
    travel: Travel, fixes: list[Fix], cfg: MarginConfig, geometry: VehicleGeometry | None = None
) -> pd.DataFrame:
    """Per-cycle state, km, equipment km, margin and source from the fixes in force, and the
    vehicle's head and tail km (:mod:`fieldlogs.pipeline.geometry`; NaN without its extent)."""
    geometry = geometry or VehicleGeometry()
    t, d = travel.t, travel.d
    n = t.size
    # state and source as codes of their few distinct texts (the enums' values), made text once
    states, sources = {PositionState.UNDETERMINED.value: 0}, {FixSource.NONE.value: 0}
    state = np.zeros(n, dtype=np.uint8)
    source = np.zeros(n, dtype=np.uint8)
    line = np.full(n, None, dtype=object)  # None: one object, every cell shares it
    track = np.full(n, None, dtype=object)
    km = np.full(n, np.nan)
    km_eq = np.full(n, np.nan)
    margin = np.full(n, np.nan)
    k_sign = np.full(n, np.nan)
    if fixes:
        t_eff = np.array([f.t_effective for f in fixes])
        idx = np.searchsorted(t_eff, t, side="right") - 1
        has = idx >= 0
        cyc = np.flatnonzero(has)
        j = idx[cyc]
        order = np.argsort(j, kind="stable")  # cycles grouped by fix in force, ascending
        groups, first = np.unique(j[order], return_index=True)
        for jj, sel in zip(groups.tolist(), np.split(cyc[order], first[1:]), strict=True):
            f = fixes[jj]  # the fix in force on cycles ``sel``: dead reckoning and margin
            if f.state == PositionState.UNDETERMINED:
                continue
            est = travel.km(f, travel.s[sel])
            km[sel] = est
            km_eq[sel] = est + (f.km_equipment_m - f.km_m)
            margin[sel] = margin_m(f, d[sel], travel.allowance[sel], cfg)
            k_sign[sel] = f.k
            state[sel] = states.setdefault(str(f.state), len(states))
            line[sel] = f.line_code
            track[sel] = f.track
            source[sel] = sources.setdefault(str(f.source), len(sources))
    head, tail = geometry.ends(km, k_sign, np.asarray(travel.cab, dtype=float))
    return pd.DataFrame(
        {
            "t": t,
            "state": text_column(state, states),
            "line_code": pd.array(line, dtype="string"),
            "track": pd.array(track, dtype="string"),
            "km_m": km,
            "km_equipment_m": km_eq,
            "speed_mps": travel.v,
            "margin_m": margin,
            "last_fix_source": pd.array(text_column(source, sources), dtype="string"),
            "km_head_m": head,
            "km_tail_m": tail,
        }
    )
