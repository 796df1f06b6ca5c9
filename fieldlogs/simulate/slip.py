"""Slip (traction: wheel faster) and slide (braking: wheel slower) episodes.

An episode multiplies the wheel's circumferential speed by 1 ± depth·w(t), w a tapered
cosine window over [t0, t1] (ramps of min(2 s, 35 % of the length)). Random episodes are
placed where they physically happen: slips while accelerating (a > 30 % of the
acceleration, v > 1 m/s), slides while braking (a < −30 % of the braking rate,
v > 3 m/s), kept whole inside that phase and at least 10 s apart; the first one goes on a
gradient-plus-curve section (|g| ≥ 5 ‰ and R ≤ 1500 m) when the run has one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

from dbtools.masks import true_runs
from fieldlogs.simulate.running import DT, Motion
from fieldlogs.simulate.scenario import Scenario, SlipCfg
from fieldlogs.simulate.track import TrackGeometry
from schemas.units import KMH_PER_S

FloatArray = npt.NDArray[np.float64]
GAP_S = 10.0
GRADE_MIN = 0.005
KAPPA_MIN = 1.0 / 1500.0


@dataclass(frozen=True)
class SlipEpisode:
    t0: float
    t1: float
    kind: str
    """'slip' or 'slide'."""
    depth: float
    on_grade_curve: bool = False

    def to_json(self) -> dict[str, object]:
        return {k: round(v, 3) if isinstance(v, float) else v for k, v in asdict(self).items()}


def place_episodes(
    scenario: Scenario, motion: Motion, geom: TrackGeometry, rng: np.random.Generator
) -> list[SlipEpisode]:
    cfg = scenario.slip
    r = scenario.running
    episodes = [
        SlipEpisode(e.t0_s, min(e.t0_s + e.duration_s, motion.duration_s), e.kind, e.depth) for e in cfg.episodes
    ]
    busy = np.zeros(motion.n, dtype=bool)

    def block(ep: SlipEpisode) -> None:
        k0 = max(int((ep.t0 - GAP_S) / DT), 0)
        busy[k0 : int((ep.t1 + GAP_S) / DT) + 1] = True

    for ep in episodes:
        block(ep)
    a, v = motion.a, motion.v
    phase = {
        "slip": (a > 0.3 * r.accel_kmh_s * KMH_PER_S) & (v > 1.0) & motion.on_rail,
        "slide": (a < -0.3 * r.brake_kmh_s * KMH_PER_S) & (v > 3.0) & motion.on_rail,
    }
    km = motion.km
    grade_curve = np.zeros(motion.n, dtype=bool)
    if cfg.on_grade_curve and (cfg.slips + cfg.slides) > 0:
        step = 10  # geometry at 10 Hz is plenty for the placement
        coarse = km[::step]
        gc = (np.abs(geom.grade(coarse)) >= GRADE_MIN) & (np.abs(geom.curvature(coarse)) >= KAPPA_MIN)
        grade_curve = np.repeat(gc, step)[: motion.n]
    todo = ["slip"] * cfg.slips + ["slide"] * cfg.slides
    if cfg.on_grade_curve and todo:
        # try the grade-and-curve episode first, as a slip if possible, else a slide
        order = ["slip", "slide"] if cfg.slips else ["slide", "slip"]
        for kind in order:
            if kind not in todo:
                continue
            placed = _place(kind, phase[kind] & grade_curve, busy, cfg, rng, on_grade_curve=True)
            if placed is not None:
                episodes.append(placed)
                block(placed)
                todo.remove(kind)
                break
    for kind in todo:
        placed = _place(kind, phase[kind], busy, cfg, rng)
        if placed is not None:
            episodes.append(placed)
            block(placed)
    return sorted(episodes, key=lambda e: e.t0)


def _place(
    kind: str,
    phase: npt.NDArray[np.bool_],
    busy: npt.NDArray[np.bool_],
    cfg: SlipCfg,
    rng: np.random.Generator,
    *,
    on_grade_curve: bool = False,
) -> SlipEpisode | None:
    """One episode wholly inside a free run of ``phase`` (shortened to fit, ≥ 1 s), or None."""
    duration = float(rng.uniform(*cfg.duration_s))
    depth = float(rng.uniform(*cfg.depth))
    starts, ends = true_runs(phase & ~busy)
    if len(starts) == 0:
        return None
    lengths = (ends - starts) * DT
    need = min(duration, float(lengths.max()))
    if need < min(1.0, cfg.duration_s[0]):
        return None
    cand = np.flatnonzero(lengths >= need)
    # start drawn uniformly over all admissible start samples
    room = ((lengths[cand] - need) / DT).astype(np.int64) + 1
    cum = np.cumsum(room)
    pick = int(rng.integers(0, int(cum[-1])))
    j = int(np.searchsorted(cum, pick, side="right"))
    k0 = int(starts[cand[j]] + pick - (cum[j] - room[j]))
    t0 = round(k0 * DT, 2)
    return SlipEpisode(t0, round(t0 + need, 2), kind, round(depth, 3), on_grade_curve)


def wheel_factor(episodes: list[SlipEpisode], t: FloatArray) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """(wheel speed / true speed, slipping flag) at times ``t``."""
    factor = np.ones_like(t)
    slipping = np.zeros(t.shape, dtype=bool)
    for ep in episodes:
        k0, k1 = np.searchsorted(t, [ep.t0, ep.t1])
        if k1 <= k0:
            continue
        tt = t[k0:k1] - ep.t0
        length = ep.t1 - ep.t0
        ramp = min(2.0, 0.35 * length)
        w = np.ones_like(tt)
        up, down = tt < ramp, tt > length - ramp
        w[up] = 0.5 * (1 - np.cos(np.pi * tt[up] / ramp))
        w[down] = 0.5 * (1 - np.cos(np.pi * (length - tt[down]) / ramp))
        sign = 1.0 if ep.kind == "slip" else -1.0
        factor[k0:k1] *= 1.0 + sign * ep.depth * w
        slipping[k0:k1] = True
    return factor, slipping
