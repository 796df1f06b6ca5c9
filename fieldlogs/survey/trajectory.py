"""The runs' reads as chains of balise passages, and travel → km through them.

**Track length.** Dead reckoning measures the length the wheels roll along a track, which
in a curve differs from the km difference of a double-track line's shared kilometrage
(:mod:`fieldlogs.pipeline.metric`): every balise km is therefore turned into the track's
own cumulative length c = c(km) and the survey works in c; a residual δc becomes a km
residual δkm = δc · dkm/dc at the balise.

**Chains.** The identified reads of one run in one segment (one line/track, one cab
direction, :mod:`fieldlogs.survey.extract`) whose balise lies on the segment's line/track,
in time order, form a chain; a read that breaks the order of the DB km in the direction of
motion is dropped (a wrong identification). Consecutive reads a, b of a chain measure
σ·(c_b − c_a) = λ·(d_b − d_a): σ the motion, d the corrected odometry travel and λ the
run's wheel scale (true ÷ configured wheel diameter, :mod:`fieldlogs.survey.wheels`).

**Travel → km.** Inside a chain the reader's position is linear in travel between two
consecutive reads (anchored at the balises' positions as surveyed), beyond its ends
c = c_end + σ·λ·(x − d_end) for at most ``extrapolate_m``: interpolation between two
balises accounts for the wheel scale by itself.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.metric import track_metric
from fieldlogs.survey.dbindex import balise_index, surveyed_balises
from fieldlogs.survey.extract import IDENTIFIED, RunSurvey
from schemas.enums import direction_sign

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class BaliseTable:
    """The DB's balises with what the survey computes from them (index = row number)."""

    frame: pd.DataFrame
    """balise_id, kind, line_code, station_code, track, track_id (its network track), signal_type, km_actual_m,
    km_equipment_m, dist_from_initial_m, c_m (track length at the km), slope (dkm/dc),
    direction (±1), cluster (balises closer than ``cluster_m`` on a track share one)."""
    row: dict[str, int]
    """balise id → row."""

    @property
    def c(self) -> FloatArray:
        return self.frame["c_m"].to_numpy(dtype=float)

    @property
    def slope(self) -> FloatArray:
        return self.frame["slope"].to_numpy(dtype=float)


def balise_table(network: Network, cluster_m: float) -> BaliseTable:
    """:class:`BaliseTable` of the network's balises the survey places
    (:func:`~fieldlogs.survey.dbindex.surveyed_balises`: I1/I2/C, and G along a line)."""
    b = surveyed_balises(network).reset_index(drop=True).copy()
    for col in ("balise_id", "kind", "line_code", "station_code", "track"):
        b[col] = b[col].astype(str)
    km = b["km_actual_m"].to_numpy(dtype=float)
    c = np.full(len(b), np.nan)
    slope = np.ones(len(b))
    cluster = np.zeros(len(b), dtype=np.int64)
    next_cluster = 0
    for key, idx in b.groupby(["line_code", "track"]).indices.items():
        line, track = cast(tuple[str, str], key)
        m = track_metric(network, str(line), str(track))
        c[idx] = m.c_of_km(km[idx])
        slope[idx] = 2.0 / np.maximum(m.c_of_km(km[idx] + 1.0) - m.c_of_km(km[idx] - 1.0), 1e-9)
        order = idx[np.argsort(km[idx], kind="stable")]
        gaps = np.diff(km[order]) >= cluster_m
        cluster[order] = next_cluster + np.concatenate([[0], np.cumsum(gaps)])
        next_cluster = int(cluster[order].max()) + 1
    b["c_m"], b["slope"], b["cluster"] = c, slope, cluster
    b["direction"] = [direction_sign(t) for t in b["track"]]
    index = network.cached("survey_balise_index", lambda: balise_index(network))
    b["track_id"] = b["balise_id"].map(index.track_ids).astype(object)
    return BaliseTable(b, {bid: i for i, bid in enumerate(b["balise_id"])})


@dataclass(frozen=True)
class Reads:
    """The chained reads of every run, sorted by (chain, t); arrays of equal length."""

    run: IntArray
    chain: IntArray
    seg: IntArray
    balise: IntArray
    """Row in the :class:`BaliseTable`."""
    d: FloatArray
    allowance: FloatArray
    motion: IntArray
    t: FloatArray

    @property
    def n(self) -> int:
        return int(self.run.size)


def _run_reads(r: int, rs: RunSurvey) -> dict[str, npt.NDArray[Any]] | None:
    """The identified reads of one run on its segment's own line/track, as arrays."""
    rd = rs.reads
    if not len(rd):
        return None
    seg = rd["seg"].to_numpy(dtype=np.int64)
    ok = (rd["status"].to_numpy(dtype=object) == IDENTIFIED) & (seg >= 0)
    if not ok.any():
        return None
    sg = rs.segments
    order = np.argsort(sg["seg"].to_numpy(dtype=np.int64), kind="stable")
    seg_ids = sg["seg"].to_numpy(dtype=np.int64)[order]
    at = np.clip(np.searchsorted(seg_ids, seg), 0, max(len(seg_ids) - 1, 0))
    ok &= (seg_ids[at] == seg) if len(seg_ids) else np.zeros(seg.size, dtype=bool)
    seg_line = sg["line_code"].to_numpy(dtype=object)[order][at]
    seg_track = sg["track"].to_numpy(dtype=object)[order][at]
    ok &= (rd["line_code"].to_numpy(dtype=object) == seg_line) & (rd["track"].to_numpy(dtype=object) == seg_track)
    if not ok.any():
        return None
    return {
        "run": np.full(int(ok.sum()), r, dtype=np.int64),
        "seg": seg[ok],
        "balise_id": rd["balise_id"].to_numpy(dtype=object)[ok],
        "d": rd["d_m"].to_numpy(dtype=float)[ok],
        "allowance": rd["allowance_m"].to_numpy(dtype=float)[ok],
        "motion": rd["motion"].to_numpy(dtype=np.int64)[ok],
        "t": rd["t"].to_numpy(dtype=float)[ok],
    }


def chained_reads(runs: Sequence[RunSurvey], table: BaliseTable) -> Reads:
    """Every run's identified reads as chains (module docstring)."""
    parts = [p for r, rs in enumerate(runs) if (p := _run_reads(r, rs)) is not None]
    if not parts:
        z = np.zeros(0, dtype=np.int64)
        return Reads(z, z, z, z, np.zeros(0), np.zeros(0), z, np.zeros(0))
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    pos = pd.Index(list(table.row)).get_indexer(pd.Index(cols.pop("balise_id")))
    row = np.where(pos >= 0, np.fromiter(table.row.values(), dtype=np.int64, count=len(table.row))[pos], -1)
    known = row >= 0
    f = pd.DataFrame({k: v[known] for k, v in cols.items()}).assign(balise=row[known].astype(np.int64))
    f = f.sort_values(["run", "seg", "t"], kind="stable", ignore_index=True)
    f = _drop_out_of_order(f, table)
    chain = np.asarray(f.groupby(["run", "seg"], sort=False).ngroup().to_numpy(), dtype=np.int64)
    return Reads(
        f["run"].to_numpy(dtype=np.int64),
        chain,
        f["seg"].to_numpy(dtype=np.int64),
        f["balise"].to_numpy(dtype=np.int64),
        f["d"].to_numpy(dtype=float),
        f["allowance"].to_numpy(dtype=float),
        f["motion"].to_numpy(dtype=np.int64),
        f["t"].to_numpy(dtype=float),
    )


def _drop_out_of_order(f: pd.DataFrame, table: BaliseTable) -> pd.DataFrame:
    """Drop reads whose DB km goes backwards in the direction of motion within a chain
    (repeated until none is left)."""
    km = table.frame["km_actual_m"].to_numpy(dtype=float)
    while len(f) > 1:
        u = f["motion"].to_numpy() * km[f["balise"].to_numpy()]
        same = (f["run"].to_numpy()[1:] == f["run"].to_numpy()[:-1]) & (
            f["seg"].to_numpy()[1:] == f["seg"].to_numpy()[:-1]
        )
        bad = np.flatnonzero(same & (np.diff(u) <= 0.0)) + 1
        if bad.size == 0:
            break
        f = f.drop(index=f.index[bad]).reset_index(drop=True)
    return f


@dataclass(frozen=True)
class Trajectory:
    """Travel → track length of one chain (module docstring, "Travel → km")."""

    d: FloatArray
    c: FloatArray
    motion: int
    scale: float
    """λ of the run (1 where unknown)."""
    reach_m: float

    def c_at(self, x: FloatArray) -> FloatArray:
        """Track length of travel ``x``; NaN beyond the reach of the chain's ends."""
        xa = np.asarray(x, dtype=float)
        out = np.interp(xa, self.d, self.c)
        before = self.c[0] - self.motion * self.scale * (self.d[0] - xa)
        after = self.c[-1] + self.motion * self.scale * (xa - self.d[-1])
        out = np.where(xa < self.d[0], before, np.where(xa > self.d[-1], after, out))
        far = (xa < self.d[0] - self.reach_m) | (xa > self.d[-1] + self.reach_m)
        return np.asarray(np.where(far, np.nan, out), dtype=float)


def trajectories(
    reads: Reads, c_anchor: FloatArray, scale: FloatArray, reach_m: float
) -> dict[tuple[int, int], Trajectory]:
    """(run, segment) → its chain's :class:`Trajectory` with the balises at ``c_anchor``
    and the runs' wheel scales ``scale`` (NaN: 1)."""
    out: dict[tuple[int, int], Trajectory] = {}
    if reads.n == 0:
        return out
    starts = np.flatnonzero(np.r_[True, reads.chain[1:] != reads.chain[:-1]])
    ends = np.r_[starts[1:], reads.n]
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        r = int(reads.run[a])
        lam = float(scale[r]) if np.isfinite(scale[r]) else 1.0
        d = reads.d[a:b]
        keep = np.r_[True, np.diff(d) > 0]  # a standstill between two reads cannot happen; guard
        out[(r, int(reads.seg[a]))] = Trajectory(
            d[keep], c_anchor[reads.balise[a:b]][keep], int(reads.motion[a]), lam, reach_m
        )
    return out
