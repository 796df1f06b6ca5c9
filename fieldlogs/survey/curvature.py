"""Curvature traces on the km of the surveyed balises: samples, coverage, mean profiles.

Each κ sample of a run (:mod:`fieldlogs.survey.extract`) is placed through its chain's
trajectory (:mod:`fieldlogs.survey.trajectory`) at

    km = km(c(x)) − σ·cab·x_r

(the reader's km moved back to the vehicle's reference point, which the feature rows refer
to: :mod:`fieldlogs.pipeline.geometry`) and turned into the curvature in the track's normal
running direction, corrected for the wheel's scale:

    κ_n = κ·σ·s_track / λ

(κ = ωz/v is left-positive in the travel direction; s_track = +1 on D/S, −1 on U; v from
the configured wheel is 1/λ times the true speed, so κ is λ times the true curvature).
Per track the runs' samples are averaged per ``profile_bin_m`` bin, first within a run,
then over runs: the mean profile κ̄(km) and the number of runs per bin.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.metric import track_metric
from fieldlogs.survey.extract import RunSurvey
from fieldlogs.survey.trajectory import Trajectory
from schemas.enums import direction_sign

FloatArray = npt.NDArray[np.float64]
TrackKey = tuple[str, str]


@dataclass(frozen=True)
class TrackSamples:
    """κ samples of one line/track from every run."""

    run: npt.NDArray[np.int64]
    km: FloatArray
    kappa: FloatArray
    """κ_n [1/m] (module docstring)."""


@dataclass(frozen=True)
class Coverage:
    """km intervals with a usable κ, per run (one line/track)."""

    run: npt.NDArray[np.int64]
    lo: FloatArray
    hi: FloatArray

    def runs_covering(self, lo: float, hi: float) -> set[int]:
        """Runs whose usable κ covers [lo, hi] entirely."""
        ok = (self.lo <= lo) & (self.hi >= hi)
        return {int(r) for r in self.run[ok]}


def place_samples(
    runs: Sequence[RunSurvey], traj: dict[tuple[int, int], Trajectory], scale: FloatArray, network: Network
) -> tuple[dict[TrackKey, TrackSamples], dict[TrackKey, Coverage]]:
    """Every run's κ samples and coverage on the km of its chains (module docstring)."""
    parts: dict[TrackKey, list[tuple[int, FloatArray, FloatArray]]] = {}
    cov: dict[TrackKey, list[tuple[int, FloatArray, FloatArray]]] = {}
    for r, rs in enumerate(runs):
        lam = float(scale[r]) if np.isfinite(scale[r]) else 1.0
        segs = rs.segments.set_index("seg")
        for seg, sub in rs.kappa.groupby("seg"):
            tj = traj.get((r, int(seg)))
            if tj is None:
                continue
            g = segs.loc[int(seg)]
            key = (str(g["line_code"]), str(g["track"]))
            to_km = _to_km(network, key, tj, int(g["cab"]), rs.reader_x_m)
            km = to_km(sub["x_m"].to_numpy(dtype=float))
            kn = sub["kappa"].to_numpy(dtype=float) * tj.motion * direction_sign(key[1]) / lam
            ok = np.isfinite(km)
            parts.setdefault(key, []).append((r, km[ok], kn[ok]))
        for seg, sub in rs.coverage.groupby("seg"):
            tj = traj.get((r, int(seg)))
            if tj is None:
                continue
            g = segs.loc[int(seg)]
            key = (str(g["line_code"]), str(g["track"]))
            to_km = _to_km(network, key, tj, int(g["cab"]), rs.reader_x_m)
            reach_lo, reach_hi = tj.d[0] - tj.reach_m, tj.d[-1] + tj.reach_m
            x0 = np.clip(sub["x0_m"].to_numpy(dtype=float), reach_lo, reach_hi)
            x1 = np.clip(sub["x1_m"].to_numpy(dtype=float), reach_lo, reach_hi)
            a, b = to_km(x0), to_km(x1)
            cov.setdefault(key, []).append((r, np.fmin(a, b), np.fmax(a, b)))
    return {k: _samples(v) for k, v in parts.items()}, {k: _coverage(v) for k, v in cov.items()}


def _to_km(network: Network, key: TrackKey, tj: Trajectory, cab: int, reader_x_m: float):  # type: ignore[no-untyped-def]
    metric = track_metric(network, key[0], key[1])
    shift = tj.motion * cab * reader_x_m

    def to_km(x: FloatArray) -> FloatArray:
        return np.asarray(metric.km_of_c(tj.c_at(x)) - shift, dtype=float)

    return to_km


def _samples(parts: list[tuple[int, FloatArray, FloatArray]]) -> TrackSamples:
    run = np.concatenate([np.full(p[1].size, p[0], dtype=np.int64) for p in parts])
    return TrackSamples(run, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]))


def _coverage(parts: list[tuple[int, FloatArray, FloatArray]]) -> Coverage:
    run = np.concatenate([np.full(p[1].size, p[0], dtype=np.int64) for p in parts])
    return Coverage(run, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]))


def mean_profile(s: TrackSamples, bin_m: float) -> pd.DataFrame:
    """km (bin centre), kappa (mean over runs of the runs' bin means), runs — sorted by km."""
    b = np.floor(s.km / bin_m).astype(np.int64)
    per_run = pd.DataFrame({"bin": b, "run": s.run, "k": s.kappa}).groupby(["bin", "run"], sort=False)["k"].mean()
    prof = per_run.groupby(level="bin").agg(["mean", "size"]).sort_index()
    return pd.DataFrame(
        {
            "km_m": (prof.index.to_numpy(dtype=float) + 0.5) * bin_m,
            "kappa": prof["mean"].to_numpy(dtype=float),
            "runs": prof["size"].to_numpy(dtype=np.int64),
        }
    )
