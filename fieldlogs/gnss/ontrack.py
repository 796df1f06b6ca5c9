"""One run's GNSS solutions on one GIS track: per receiver-epoch, per epoch, and as km [S002].

:func:`solve_on_track` runs :func:`fieldlogs.gnss.position.position_run` (pre-checks,
constrained solution with FDE, clock coasting, antenna-distance check, the unconstrained
solution beside it) on the track's polyline without a prior, so the solutions do not depend
on the pipeline's estimate and are the same for the aid and for ``trainpos gnss position``;
the run's SBAS/MSAS messages apply when it has them (``gnss.sbas``).

* ``table``: one row per receiver-epoch (the core's columns, see ``position_run``) plus the
  common ``epoch`` (receivers' epochs within 20 ms), ``km_m`` (the reference point's km,
  :meth:`~fieldlogs.gnss.gis.GisTrack.km_of_s`) and ``ok`` = available and antenna-distance
  check passed;
* ``best``: per epoch with an ``ok`` row, the row of the receiver with the smallest stated
  uncertainty U (the receivers share the satellites' and the atmosphere's errors, so averaging
  them would not shrink U as if they were independent).

:class:`TrackEvidence` compares the fits on two tracks of a line (the paper's up/down use of
the constrained solution): per receiver-epoch where both tracks have an ``ok`` solution from
the same number of satellites with redundancy (dof ≥ 1), the excess of the test statistic
T = Σ v²/σ² on the track in force over the other's, summed over the epoch's receivers. With
Gaussian errors twice the log-likelihood ratio of the two tracks is that excess; because
multipath and orbit errors are correlated over minutes, the decision rule uses the *median*
over a window and the share of epochs favouring the other track instead of the sum (which would
count correlated epochs as independent evidence).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fieldlogs.gnss.gis import GisTrack
from fieldlogs.gnss.position import PositionConfig, PositionResult, position_run
from fieldlogs.gnss.runinputs import RunGnss
from fieldlogs.gnss.skymask import SkyMask

#: Columns of ``TrackSolutions.best``.
BEST_COLUMNS = (
    "t", "gnss_time_s", "receiver", "km_m", "s_m", "uncertainty_m", "sigma_m", "n_used", "n_excluded", "dof",
    "test", "residual_rms_m", "status", "clock_aided",
)  # fmt: skip


@dataclass
class TrackSolutions:
    """Solutions of one run on one track for one facing (module docstring)."""

    line_code: str
    track: str
    direction: int
    """+1: the vehicle's F end faces increasing km; −1: decreasing."""
    result: PositionResult
    table: pd.DataFrame
    best: pd.DataFrame
    """Indexed by epoch."""

    def at(self, epoch: int) -> pd.Series | None:
        """The best solution of ``epoch`` (None when no receiver has an ``ok`` one)."""
        if epoch not in self.best.index:
            return None
        row = self.best.loc[epoch]
        return row if isinstance(row, pd.Series) else None


def solve_on_track(
    g: RunGnss, track: GisTrack, direction: int, cfg: PositionConfig, *, sky_mask: SkyMask | None = None
) -> TrackSolutions:
    """Every epoch of the run on ``track`` (module docstring)."""
    res = position_run(
        g.obs,
        g.nav,
        track.line,
        g.antennas,
        iono=g.iono,
        sky_mask=sky_mask,
        direction=float(direction),
        cfg=cfg,
        sbas=g.sbas if cfg.use_sbas else None,
    )
    tb = res.epochs.copy()
    tb["epoch"] = g.epoch_of(tb["t"].to_numpy(dtype=float))
    tb["km_m"] = track.km_of_s(tb["s_m"].to_numpy(dtype=float))
    dist_ok = tb["antenna_distance_ok"].to_numpy(bool) if "antenna_distance_ok" in tb else np.ones(len(tb), bool)
    tb["ok"] = tb["available"].to_numpy(bool) & dist_ok
    best = tb[tb["ok"]].sort_values(["epoch", "uncertainty_m"], kind="stable").drop_duplicates("epoch")
    return TrackSolutions(track.line_code, track.track, direction, res, tb, best.set_index("epoch")[list(BEST_COLUMNS)])


@dataclass(frozen=True)
class TrackEvidence:
    """Per epoch: time and the test-statistic excess of the track in force over another track."""

    other_track: str
    t: np.ndarray
    excess: np.ndarray

    @classmethod
    def between(cls, this: TrackSolutions, other: TrackSolutions) -> TrackEvidence:
        cols = ["receiver", "epoch", "t", "test", "dof", "n_used"]
        a = this.table.loc[this.table["ok"], cols]
        b = other.table.loc[other.table["ok"], cols]
        m = a.merge(b, on=["receiver", "epoch"], suffixes=("", "_o"))
        m = m[(m["n_used"] == m["n_used_o"]) & (m["dof"] >= 1) & (m["dof_o"] >= 1)]
        per = (m["test"] - m["test_o"]).groupby(m["epoch"]).sum()
        t = m.groupby("epoch")["t"].min().reindex(per.index)
        order = np.argsort(t.to_numpy(dtype=float), kind="stable")
        return cls(other.track, t.to_numpy(dtype=float)[order], per.to_numpy(dtype=float)[order])

    def window(self, t_now: float, window_s: float) -> np.ndarray:
        """Excesses of the epochs in (t_now − window_s, t_now]."""
        lo = int(np.searchsorted(self.t, t_now - window_s, side="right"))
        hi = int(np.searchsorted(self.t, t_now, side="right"))
        return self.excess[lo:hi]

    def far_better(self, t_now: float, window_s: float, min_epochs: int, chi2: float, share: float) -> bool:
        """The other track fits far better over the window (module docstring)."""
        w = self.window(t_now, window_s)
        return bool(w.size >= min_epochs and np.median(w) > chi2 and np.mean(w > 0) >= share)
