"""Stage 5: the corrected :class:`~fieldlogs.pipeline.types.Odometry` from the episodes.

Output time base
    Episodes are found on the aligned arrays and written back shifted by the pulse delay, so
    ``d``, ``v`` and the episode indices refer to the cycle grid of ``cycles.t`` (the
    correction is retroactive from the start point, as the onboard unit recomputes it once
    it detects the slip at ``t_detect``, which is the clock time of the detection cycle).

Distance
    Over an episode the distance is the pulse distance at its start (plus the offsets of
    earlier episodes) + ∫ v dt of its corrected speed; after it the pulses continue with a
    constant offset, so ``d`` is continuous and never decreases. With a ground speed (the
    radar [S004]) an episode's speed is the fused one of :mod:`.fusion`. A truncated episode
    (the data end first) holds its last speed to the end.

Allowance (eq. 13)
    ``allowance[k]`` = Σ over finished episodes of ½·Δa·T² (T = their correction time) plus,
    inside a running episode, ½·Δa·(t − t_start)² (at most its budget), plus the fail-safe
    watches' growth (stage 4). It is continuous, never decreases, and equals the full eq. 13
    budget from each episode's end on (22.8 m for T = 10 s). Departure with a ground speed:
    an episode's budget is the fused distance's B of :mod:`.fusion` (from the radar's σ,
    eq. 13 only over the radar's gaps), inside the episode B up to the cycle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.detection import Detections
from fieldlogs.pipeline.odometry.diagnostics import EpisodeDiagnostics, OdometryDiagnostics
from fieldlogs.pipeline.odometry.episodes import Episode
from fieldlogs.pipeline.odometry.signals import finite_or_none
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.odometry.watch import Watch
from fieldlogs.pipeline.types import (
    FailsafeWatch,
    FloatArray,
    Odometry,
    SlipEpisode,
    SpeedSource,
    slip_budget_m,
)
from schemas.units import mps2_to_kmh_s


@dataclass(frozen=True, eq=False)
class _Segment:
    """One episode on the output grid: cycles s..e, its distance and speed there."""

    s: int
    e: int
    v: FloatArray
    """Corrected speed on s..e [m/s]."""
    d: FloatArray
    """Corrected distance on s..e [m]."""
    offset_before: float
    """d − d_pulse before the episode [m]."""
    offset_after: float
    """d − d_pulse from its end on [m]."""
    budget: float
    """Error budget [m]."""
    source: SpeedSource
    grow: FloatArray | None = None
    """Budget from s to each cycle up to e (a ground-speed episode; None: eq. 13's)."""


def assemble(
    s: AlignedStreams,
    d: Detections,
    cfg: OdometryConfig,
    episodes: Sequence[Episode],
) -> Odometry:
    """Stage 5: distance, speed, slipping flags and allowance with the episodes applied;
    the public episodes and the diagnostics."""
    n = s.n
    segs = _segments(s, cfg, episodes)
    v = s.v_pulse.copy()
    slipping = np.zeros(n, dtype=bool)
    off_step = np.zeros(n + 1)
    allow_step = np.zeros(n + 1)
    for g in segs:
        v[g.s + 1 : g.e + 1] = g.v[1:]
        slipping[g.s + 1 : g.e + 1] = True
        off_step[g.e + 1] += g.offset_after - g.offset_before
        allow_step[g.e + 1] += g.budget
    dist = s.d_pulse + np.cumsum(off_step)[:n]
    allowance = np.cumsum(allow_step)[:n]
    da = cfg.delta_a_mps2
    for g in segs:
        dist[g.s : g.e + 1] = g.d
        if g.grow is None:
            grow = 0.5 * da * (s.t[g.s + 1 : g.e + 1] - s.t[g.s]) ** 2
        else:
            grow = g.grow[1:]
        allowance[g.s + 1 : g.e + 1] += np.minimum(grow, g.budget)
    watches = [ep.watch for ep in episodes]
    for w in [*watches, *(r for ep in episodes for r in ep.rewatches)]:
        if w is not None and w.grow.size:
            allowance[w.cycles] += w.grow
            allowance[w.cycles[-1] + 1 :] += w.grow[-1]
    public = [_public(s, ep, g, w) for ep, g, w in zip(episodes, segs, watches, strict=True)]
    diag = OdometryDiagnostics(s.delay, tuple(_diagnostics(s, d, ep) for ep in episodes))
    return Odometry(dist, v, slipping, allowance, public, diag)


def _segments(s: AlignedStreams, cfg: OdometryConfig, episodes: Sequence[Episode]) -> tuple[_Segment, ...]:
    """The episodes on the output grid, each continuing the distance of the one before."""
    out: list[_Segment] = []
    offset = 0.0
    for ep in episodes:
        g = _segment(s, cfg, ep, offset)
        out.append(g)
        offset = g.offset_after
    return tuple(out)


def _segment(s: AlignedStreams, cfg: OdometryConfig, ep: Episode, offset: float) -> _Segment:
    """One episode on the output grid, its distance starting ``offset`` above the pulses."""
    n = s.n
    i, e = ep.i_start - s.delay, ep.i_end - s.delay
    v_in = ep.v_in
    path = ep.budget
    if ep.truncated and e < n - 1:  # data ended mid-correction: hold the speed
        v_in = np.concatenate([v_in, np.full(n - 1 - e, v_in[-1])])
        if path is not None:
            path = np.concatenate([path, np.full(n - 1 - e, path[-1])])
        e = n - 1
    inc = np.concatenate([[0.0], v_in[1:] * s.dt[i + 1 : e + 1]])
    d_seg = (s.d_pulse[i] + offset) + np.cumsum(inc)
    after = float(d_seg[-1] - s.d_pulse[e])
    if path is not None:  # fused with a ground speed: its budget B
        source: SpeedSource = "radar" if ep.ground_share > 0 else "inertial"
        return _Segment(i, e, v_in, d_seg, offset, after, float(path[-1]), source, path)
    budget = slip_budget_m(float(s.t[e] - s.t[i]), cfg.delta_a_mps2)
    return _Segment(i, e, v_in, d_seg, offset, after, budget, "inertial")


def _public(s: AlignedStreams, ep: Episode, g: _Segment, w: Watch | None) -> SlipEpisode:
    t = s.t
    watch = None
    if w is not None:
        watch = FailsafeWatch(
            end_t=float(t[w.end - s.delay]),
            allowance_m=float(w.grow[-1]) if w.grow.size else 0.0,
            readhered=w.readhered,
            speed_source=w.source,
        )
    start = ep.integration.start
    return SlipEpisode(
        ep.kind,
        float(t[ep.i_detect]),
        float(t[g.s]),
        float(t[g.e]),
        g.s,
        g.e,
        float(s.d_pulse[g.e] - s.d_pulse[g.s]),
        float(g.d[-1] - g.d[0]),
        g.budget,
        ep.readhered,
        ep.failsafe,
        criterion=ep.criterion,
        start_found=ep.start_found,
        theta0_rad=start.theta0,
        v0_mps=start.v0,
        truncated=ep.truncated,
        speed_source=g.source,
        speed_update_m=ep.speed_update_m if g.source == "inertial" else 0.0,  # radar: the update is not used
        watch=watch,
        start_trusted=ep.start_trusted,
        after_failsafe_t=tuple(x for x in ep.redetect_t if ep.failsafe and x > t[ep.i_end]),
    )


def _diagnostics(s: AlignedStreams, d: Detections, ep: Episode) -> EpisodeDiagnostics:
    k, start = ep.i_detect, ep.integration.start
    diag = EpisodeDiagnostics(
        i_detect_aligned=k,
        i_start_aligned=ep.i_start,
        i_end_aligned=ep.i_end,
        i_settled_aligned=ep.i_settled,
        lookback_s=float(s.t[k] - s.t[ep.i_start]),
        redetect_t=ep.redetect_t,
        echo_t=ep.echo_t,
        diff_at_detect_kmh_s=mps2_to_kmh_s(float(s.diff[k])),
        ax_at_detect_kmh_s=mps2_to_kmh_s(float(s.axs[k])),
        ap_at_detect_kmh_s=mps2_to_kmh_s(float(s.aps[k])),
        v_pulse_at_detect_mps=float(s.vp1[k]),
        residual_at_detect_kmh_s=finite_or_none(mps2_to_kmh_s(float(d.residual[k]))),
        psi0_rad=start.psi0,
        theta_end_rad=ep.theta_end,
        gyro_bias_rad_s=start.bias,
        theta_clipped=start.clipped,
        end_speed_error_mps=finite_or_none(ep.end_speed_error),
    )
    f = ep.fusion
    if f is None:
        return diag
    return replace(  # the fused correction's cross-check figures
        diag,
        ground_e_at_detect_mps=finite_or_none(float(d.ground_e[k])) if d.ground_e is not None else None,
        ground_refused=f.refused,
        ground_reseated=f.reseated,
        ground_share=ep.ground_share,
        inertial_dev_mps=f.inertial_dev_mps(ep.i_end - ep.i_start + 1),
    )
