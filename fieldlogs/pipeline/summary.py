"""The pipeline's outputs of one run: the events frame and the headline summary.

``summary.json`` holds what audits aggregate: distance, route, state shares, correction
statistics (:mod:`fieldlogs.pipeline.corrections` — balise corrections under the plain
names, all absolute corrections under ``all_corrections``), feature refusals by
diagnostic, slips, fail-safes, anomalies, GPS trust, the largest margin and, for runs with
a ``truth`` stream, the comparison with it; with a radar, what it gave the odometry and the
wheel calibration.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.corrections import run_correction_stats
from fieldlogs.pipeline.types import Event, GpsAnalysis, Odometry, SlipEpisode
from fieldlogs.runs.handle import Run
from schemas.enums import CORRECTION_EVENTS, SLIP_EVENTS, EventType, PositionState
from schemas.jsonable import jsonable
from schemas.outputs import EVENTS

#: Decimals kept in the events' ``detail`` JSON (µm, µs: below every sensor's resolution).
DETAIL_DIGITS = 6


TrackClaims = dict[str, tuple[int, str | None, str | None]]
"""track_id → (claimed cycles, line_code, track): the display names of the track (None off a line)."""


def _name(v: Any) -> str | None:
    """A display name of the positions (line code, local track name); None when missing."""
    return None if v is None or (isinstance(v, float) and np.isnan(v)) or v is pd.NA else str(v)


def track_claims(pos: pd.DataFrame) -> TrackClaims:
    """Cycles claimed (state not undetermined) on each track id of ``pos``."""
    claimed = pos[(pos["state"].astype(str) != PositionState.UNDETERMINED.value) & pos["track_id"].notna()]
    if claimed.empty:
        return {}
    g = claimed.groupby(claimed["track_id"].astype(str), sort=True)
    n, lines, tracks = g.size(), g["line_code"].first(), g["track"].first()
    return {str(tid): (int(n[tid]), _name(lines[tid]), _name(tracks[tid])) for tid in n.index}


def merge_claims(parts: Iterable[TrackClaims]) -> TrackClaims:
    """The claims of consecutive spans added up (names as first seen)."""
    out: TrackClaims = {}
    for part in parts:
        for tid, (n, line, track) in part.items():
            prev = out.get(tid)
            out[tid] = (n + prev[0], prev[1], prev[2]) if prev else (n, line, track)
    return out


def main_track(claims: TrackClaims) -> tuple[str | None, str | None, str | None]:
    """(track_id, line_code, track) of a run's route: the track claimed on most cycles; ties
    broken by line, local name, then id (on a line-only DB the order of the (line, track)
    routes, so ``track_id`` is the implied id of the summary's ``line_code``/``track``)."""
    if not claims:
        return None, None, None
    tid, (_, line, track) = min(claims.items(), key=lambda kv: (-kv[1][0], kv[1][1] or "", kv[1][2] or "", kv[0]))
    return tid, line, track


def episode_events(odo: Odometry, km: np.ndarray) -> list[Event]:
    """One ``slip``/``slide`` event per odometry episode, at its correction start point."""
    events = []
    for ep in odo.episodes:
        i = min(max(ep.i_start, 0), len(km) - 1) if len(km) else 0
        events.append(
            Event(
                ep.t_start,
                EventType(ep.kind),
                float(km[i]) if len(km) and np.isfinite(km[i]) else None,
                detail=ep.event_detail(),
            )
        )
    return events


#: Events that are warnings about the input (their detail's message goes to summary ``warnings``).
WARNING_EVENTS = (EventType.CLOCK_OFFSET, EventType.BALISE_CLOCK, EventType.WHEEL_SCALE)


def events_frame(events: list[Event]) -> pd.DataFrame:
    rows = [
        {
            "t": e.t,
            "type": str(e.type),
            "km_m": e.km_m,
            "correction_m": e.correction_m,
            "correction_pct": e.correction_pct,
            "detail": json.dumps(jsonable(e.detail, DETAIL_DIGITS), ensure_ascii=False, sort_keys=True),
        }
        for e in events
    ]
    frame = pd.DataFrame(rows, columns=EVENTS.column_names)
    for c in ("t", "km_m", "correction_m", "correction_pct"):
        frame[c] = pd.to_numeric(frame[c]).astype("float64")
    for c in ("type", "detail"):
        frame[c] = frame[c].astype("string")
    return frame


@dataclass
class RunParts:
    """What the summary takes from the positions, the odometry and the GPS analysis, in a
    form two consecutive spans of one run can be merged in (:meth:`merged`): counts, sums,
    extremes, first and last values — so a long run replayed in windows
    (:mod:`fieldlogs.pipeline.windows`) is summarised without holding its positions.

    The summary of a whole run is :func:`summarise_parts` of ``RunParts.of`` its outputs;
    the windowed replay merges the parts of its kept spans."""

    cycles: int
    t_first: float | None
    t_last: float | None
    states: dict[str, int]
    """Cycles per state, most frequent first."""
    routes: dict[tuple[str, str], int]
    """Claimed (not undetermined) cycles per (line_code, track)."""
    first_claimed_t: float | None
    max_margin_m: float | None
    distance_m: float
    episodes: list[SlipEpisode]
    gps_decisions: int
    gps_fixes: int
    gps_trusted: int
    ground: dict[str, Any] = field(default_factory=dict)
    """``radar`` and ``wheel_calibration`` of the summary (empty without a ground-speed sensor)."""
    ground_cycles: int = 0
    """Cycles the ground report is of (the weight of its shares when spans are merged)."""
    tracks: TrackClaims = field(default_factory=dict)
    """Claimed cycles per track id, with the track's display names (:func:`track_claims`)."""

    @classmethod
    def of(
        cls,
        pos: pd.DataFrame,
        odo: Odometry,
        gps: GpsAnalysis | None,
        wheel_diameter_m: float | None,
        *,
        wheel_scale: float = 1.0,
        distance_m: float | None = None,
    ) -> RunParts:
        """The parts of one span's outputs; ``distance_m`` overrides the odometry's last
        distance (a window's kept span does not start at 0)."""
        states = {str(k): int(v) for k, v in pos["state"].value_counts().items()}
        claimed = pos[pos["state"] != PositionState.UNDETERMINED.value]
        routes = claimed.groupby(["line_code", "track"], dropna=True).size()
        fixes: pd.DataFrame = gps.fixes if gps is not None and gps.fixes is not None else pd.DataFrame()
        has_fixes = len(fixes) > 0
        ground = _ground(odo, wheel_diameter_m, wheel_scale)
        return cls(
            cycles=len(pos),
            t_first=float(pos["t"].iloc[0]) if len(pos) else None,
            t_last=float(pos["t"].iloc[-1]) if len(pos) else None,
            states=states,
            routes={(str(k[0]), str(k[1])): int(v) for k, v in zip(routes.index, routes.to_numpy(), strict=True)},
            first_claimed_t=float(claimed["t"].iloc[0]) if len(claimed) else None,
            max_margin_m=float(pos["margin_m"].max()) if pos["margin_m"].notna().any() else None,
            distance_m=distance_m if distance_m is not None else (float(odo.d[-1]) if odo.d.size else 0.0),
            episodes=list(odo.episodes),
            gps_decisions=len(gps.decisions) if gps else 0,
            gps_fixes=len(fixes) if has_fixes else 0,
            gps_trusted=int(fixes["trusted"].sum()) if has_fixes else 0,
            ground=ground,
            ground_cycles=len(pos) if ground else 0,
            tracks=track_claims(pos),
        )

    @staticmethod
    def merged(parts: list[RunParts]) -> RunParts:
        """Consecutive spans as one (in time order)."""
        states: dict[str, int] = {}
        routes: dict[tuple[str, str], int] = {}
        for p in parts:
            for k, v in p.states.items():
                states[k] = states.get(k, 0) + v
            for r, v in p.routes.items():
                routes[r] = routes.get(r, 0) + v
        firsts = [p.t_first for p in parts if p.t_first is not None]
        lasts = [p.t_last for p in parts if p.t_last is not None]
        claims = [p.first_claimed_t for p in parts if p.first_claimed_t is not None]
        margins = [p.max_margin_m for p in parts if p.max_margin_m is not None]
        return RunParts(
            cycles=sum(p.cycles for p in parts),
            t_first=firsts[0] if firsts else None,
            t_last=lasts[-1] if lasts else None,
            states=dict(sorted(states.items(), key=lambda kv: -kv[1])),  # stable: ties keep first seen
            routes=routes,
            first_claimed_t=claims[0] if claims else None,
            max_margin_m=max(margins) if margins else None,
            distance_m=sum(p.distance_m for p in parts),
            episodes=[e for p in parts for e in p.episodes],
            gps_decisions=sum(p.gps_decisions for p in parts),
            gps_fixes=sum(p.gps_fixes for p in parts),
            gps_trusted=sum(p.gps_trusted for p in parts),
            ground=_merged_ground(parts),
            ground_cycles=sum(p.ground_cycles for p in parts),
            tracks=merge_claims(p.tracks for p in parts),
        )


def summarise(
    run: Run,
    network: Network,
    cfg: PipelineConfig,
    pos: pd.DataFrame,
    ev: pd.DataFrame,
    odo: Odometry,
    gps: GpsAnalysis | None,
    *,
    wheel_scale: float = 1.0,
) -> dict[str, Any]:
    """Headline figures of one run (what audits aggregate); ``wheel_scale``: the scale the
    pulse distance was divided by (:mod:`fieldlogs.pipeline.wheelscale`), so the radar's wheel
    calibration is stated against run.json's diameter."""
    meta = run.meta
    assert meta is not None
    parts = RunParts.of(pos, odo, gps, meta.wheel_diameter_m, wheel_scale=wheel_scale)
    return summarise_parts(run, network, cfg, parts, ev)


def summarise_parts(
    run: Run, network: Network, cfg: PipelineConfig, parts: RunParts, ev: pd.DataFrame
) -> dict[str, Any]:
    """:func:`summarise` from the (merged) parts of a run and all its events."""
    meta = run.meta
    assert meta is not None
    corr = ev[ev["type"].isin(CORRECTION_EVENTS)]
    refused = ev[ev["type"] == EventType.FEATURE_REFUSED]
    warned = ev[ev["type"].isin([str(t) for t in WARNING_EVENTS])]
    reasons: dict[str, int] = {}
    for d in refused["detail"]:
        for r in json.loads(d).get("failed", []):
            reasons[r] = reasons.get(r, 0) + 1
    best = max(sorted(parts.routes), key=lambda r: parts.routes[r]) if parts.routes else None
    main_route: tuple[str | None, str | None] = best if best is not None else (None, None)
    span = (parts.t_last - parts.t_first) if parts.t_first is not None and parts.t_last is not None else 0.0
    return {
        "run_id": run.run_id,
        "vehicle_id": meta.vehicle_id,
        "vehicle_kind": meta.vehicle_kind,
        "db_version": network.meta.get("db_version"),
        "config": cfg.to_dict(),
        "duration_s": float(span),
        "distance_m": parts.distance_m,
        "line_code": main_route[0],
        "track": main_route[1],
        "track_id": main_track(parts.tracks)[0],
        "first_determined_t": parts.first_claimed_t,
        "state_share": {k: round(v / parts.cycles, 6) for k, v in parts.states.items()},
        **run_correction_stats(ev, population="balise"),
        "all_corrections": run_correction_stats(ev, population="all"),
        "n_balise_corrections": int((corr["type"] == EventType.BALISE_CORRECTION).sum()),
        "n_feature_corrections": int((corr["type"] == EventType.FEATURE_CORRECTION).sum()),
        "n_feature_refused": len(refused),
        "feature_refusals": reasons,
        "n_slips": int(ev["type"].isin(SLIP_EVENTS).sum()),
        "n_failsafe": int((ev["type"] == EventType.FAILSAFE).sum()),
        "n_anomalies": int((ev["type"] == EventType.BALISE_ANOMALY).sum()),
        "gps_decisions": parts.gps_decisions,
        "gps_trusted_share": parts.gps_trusted / parts.gps_fixes if parts.gps_fixes else None,
        "max_margin_m": parts.max_margin_m,
        "warnings": [
            str(json.loads(d).get("message", t)) for t, d in zip(warned["type"], warned["detail"], strict=True)
        ],
        "episodes": [asdict(e) for e in parts.episodes],
        **parts.ground,
    }


def _ground(odo: Odometry, wheel_diameter_m: float | None, wheel_scale: float = 1.0) -> dict[str, Any]:
    """With a ground-speed sensor (the radar): what it gave the odometry (``radar``) and the
    wheel calibration (``wheel_calibration``: true/nominal diameter with its 95 % interval);
    nothing without one. Measured on pulses divided by ``wheel_scale`` (ratio r·s), it is
    stated against the nominal wheel: ratio and half-width divided by s."""
    if odo.ground is None or wheel_diameter_m is None:
        return {}
    ground = odo.ground
    if wheel_scale != 1.0 and ground.calibration is not None:
        cal = ground.calibration
        cal = replace(cal, ratio=cal.ratio / wheel_scale, half_width=cal.half_width / wheel_scale)
        ground = replace(ground, calibration=cal)
    report = ground.to_json(wheel_diameter_m)
    return {"radar": report, "wheel_calibration": report.pop("wheel_calibration")}


def _merged_ground(parts: list[RunParts]) -> dict[str, Any]:
    """The radar's report over consecutive spans: shares weighted by the spans' cycles, the
    time against the cab summed, the wheel calibration the inverse-variance mean of the
    spans' ratios (95 % half-widths combined as 1/√Σ h⁻²), distances and stretches summed.
    One span: its report unchanged."""
    with_ground = [p for p in parts if p.ground]
    if len(with_ground) <= 1:
        return dict(with_ground[0].ground) if with_ground else {}
    n = sum(p.ground_cycles for p in with_ground) or 1
    radar = dict(with_ground[0].ground["radar"])
    for key in ("covered_share", "low_speed_share"):
        radar[key] = sum(p.ground["radar"][key] * p.ground_cycles for p in with_ground) / n
    radar["against_cab_s"] = sum(p.ground["radar"]["against_cab_s"] for p in with_ground)
    cals = [
        c for p in with_ground if (c := p.ground.get("wheel_calibration")) and c["ratio_ci95"][1] > c["ratio_ci95"][0]
    ]
    if not cals:
        return {"radar": radar, "wheel_calibration": None}
    weights = [1.0 / ((c["ratio_ci95"][1] - c["ratio_ci95"][0]) / 2.0) ** 2 for c in cals]
    ratio = sum(w * c["ratio"] for w, c in zip(weights, cals, strict=True)) / sum(weights)
    half = 1.0 / float(np.sqrt(sum(weights)))
    nominal = cals[0]["diameter_m"] / cals[0]["ratio"]
    cal = {
        **cals[0],
        "ratio": ratio,
        "ratio_ci95": [ratio - half, ratio + half],
        "diameter_m": ratio * nominal,
        "diameter_ci95_m": [(ratio - half) * nominal, (ratio + half) * nominal],
        "wear_pct": 100.0 * (1.0 - ratio),
        "distance_m": sum(c["distance_m"] for c in cals),
        "stretches": sum(c["stretches"] for c in cals),
        "applied": any(c["applied"] for c in cals),
        "applied_from_t": next((c["applied_from_t"] for c in cals if c.get("applied_from_t") is not None), None),
    }
    return {"radar": radar, "wheel_calibration": cal}
