"""Feature-point tables of the onboard DB as the feature aids read them [S000 Table 1].

Six rows per curve, attributes as seen running in the track's normal direction (D/S: km
increasing, U: decreasing): entry straight start/end, curve entry (radius R, left/right),
curve exit, exit straight start/end. In travel coordinates u = σ·km (σ = ±1 km per metre of
travel) the rows met in travel order are 1…6 when σ equals the track's normal direction,
else 6…1 with left/right swapped.

The same holds for ``track_feature_points`` with pos (distance from the track's begin) in
place of km and the normal direction begin → end (pos increasing): :func:`load_tables` with
``where = ("track_id",)``, ``position = "pos_m"`` gives one table per track (its
``line_code`` empty, its ``track`` the track id, ``sense`` +1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.pipeline.types import FloatArray
from schemas.enums import Attribute, Track, direction_sign

if TYPE_CHECKING:
    from dbtools.network import Network


@dataclass(frozen=True, eq=False)
class FeatureTable:
    """Valid features of one line/track, rows 1…6 in the track's normal direction."""

    line_code: str
    track: str
    feature_id: npt.NDArray[np.object_]
    km: FloatArray
    """(m, 6) km of rows 1…6."""
    radius_m: FloatArray
    left: npt.NDArray[np.bool_]
    """Left curve as seen in the track's normal direction."""
    sense: int = 0
    """The normal direction as the sign of the position per metre (0: from ``track``, U −1)."""

    @property
    def normal(self) -> int:
        return self.sense or direction_sign(self.track)

    def travel_rows(self, sdir: int) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int_]]:
        """(u, km, expected κ sign) with rows in travel order for km direction ``sdir``."""
        km = self.km if sdir == self.normal else self.km[:, ::-1]
        sign = np.where(self.left, 1, -1) * (1 if sdir == self.normal else -1)
        return sdir * km, km, sign


@dataclass(frozen=True, eq=False)
class Candidate:
    """One feature as met in one travel direction (the handle passed to ``evaluate``)."""

    feature_id: str
    line_code: str
    track: str
    sdir: int
    """km per metre of travel (±1)."""
    reversed: bool
    """Running against the track's normal direction (rows met 6…1, left/right swapped)."""
    u: FloatArray
    """Rows r1…r6 in travel order as u = sdir·km (increasing)."""
    km: FloatArray
    """km of r1…r6 (travel order)."""
    radius_m: float
    sign: int
    """Expected κ sign in the travel direction (+1 left)."""
    margin_m: float
    """Search margin w at scheduling time [m]."""
    segment: int
    """Cab-direction segment (number of cab changes before it)."""


def load_tables(
    fp: pd.DataFrame, where: tuple[str, ...] = ("line_code", "track"), position: str = "km_m"
) -> tuple[dict[tuple[str, str], FeatureTable], list[dict[str, Any]]]:
    """Group the feature-point rows per line/track (vectorised: national DBs hold ~10,000
    features); invalid features are skipped with a reason. ``where`` and ``position``: the
    columns naming the track and the row position (module docstring for the track form)."""
    tables: dict[tuple[str, str], FeatureTable] = {}
    skipped: list[dict[str, Any]] = []
    if fp is None or fp.empty:
        return tables, skipped
    by_track = where == ("track_id",)
    keys = [*where, "feature_id"]
    f = pd.DataFrame({k: fp[k].astype(str).to_numpy() for k in keys})
    f["km"] = pd.to_numeric(fp[position], errors="coerce").to_numpy(dtype=float)
    f["radius"] = pd.to_numeric(fp["radius_m"], errors="coerce").to_numpy(dtype=float)
    f["attr"] = fp["attribute"].astype(str).to_numpy()
    normal = np.ones(len(f)) if by_track else np.where(f["track"].to_numpy() == Track.UP, -1.0, 1.0)
    # running order: seq where the table has it, else the position in the track's normal direction
    seq = fp["seq"] if "seq" in fp.columns else None
    f["order"] = seq.to_numpy(dtype=float) if seq is not None and seq.notna().all() else f["km"] * normal
    f = f.sort_values([*keys, "order"], kind="stable").reset_index(drop=True)
    group = f.groupby(keys, sort=False).ngroup().to_numpy()
    size = np.bincount(group)
    first = np.searchsorted(group, np.arange(size.size))
    head = f.iloc[first].reset_index(drop=True)
    why = np.full(size.size, "", dtype=object)
    why[size != 6] = [f"{k} rows (6 expected)" for k in size[size != 6]]
    six = np.flatnonzero(size == 6)
    rows = first[six][:, None] + np.arange(6)
    km = f["km"].to_numpy()[rows]
    sense = np.ones(six.size) if by_track else np.where(head["track"].to_numpy()[six] == Track.UP, -1.0, 1.0)
    u = km * sense[:, None]
    attr3 = f["attr"].to_numpy()[rows[:, 2]]
    r3 = f["radius"].to_numpy()[rows[:, 2]]
    bad_order = ~np.isfinite(km).all(axis=1) | (np.diff(u, axis=1) < 0).any(axis=1) | (u[:, 3] <= u[:, 2])
    checks = [
        (bad_order, f"{'pos' if by_track else 'km'} not in running order"),
        (~(r3 > 0), "row 3 radius is not > 0"),
        (~np.isin(attr3, [Attribute.LEFT.value, Attribute.RIGHT.value]), "row 3 attribute is not left/right"),
    ]
    for bad, reason in checks:  # the last failing check wins; any reason is enough
        why[six[bad]] = reason
    for j in np.flatnonzero(why != ""):
        skipped.append({**{k: head.at[j, k] for k in keys}, "reason": why[j]})
    ok = why[six] == ""
    good = six[ok]
    km, r3, left = km[ok], r3[ok], attr3[ok] == Attribute.LEFT.value
    lt = head.loc[good, list(where)].to_numpy()
    for key in {tuple(str(x) for x in row) for row in lt}:
        sel = np.all(lt == np.array(key, dtype=object), axis=1)
        line, track = ("", key[0]) if by_track else key
        ids = head.loc[good[sel], "feature_id"].to_numpy(dtype=object)
        tables[(line, track)] = FeatureTable(line, track, ids, km[sel], r3[sel], left[sel], 1 if by_track else 0)
    return tables, skipped


def line_feature_tables(network: Network) -> tuple[dict[tuple[str, str], FeatureTable], list[dict[str, Any]]]:
    """:func:`load_tables` of the network's line-form feature points, built once per loaded
    network (:meth:`Network.cached`) and shared — by every run replayed with it, and by every
    window of a long run (:mod:`fieldlogs.pipeline.windows`), which rebuilt them each time.
    A function of the DB alone; its tables and list are read, never modified."""
    return network.cached(("features", "line_tables"), lambda: load_tables(network.feature_points))
