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
from dataclasses import asdict, replace
from typing import Any

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.io import Run
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.corrections import run_correction_stats
from fieldlogs.pipeline.types import Event, GpsAnalysis, Odometry
from schemas.enums import CORRECTION_EVENTS, SLIP_EVENTS, EventType, PositionState
from schemas.jsonable import jsonable
from schemas.outputs import EVENTS

#: Decimals kept in the events' ``detail`` JSON (µm, µs: below every sensor's resolution).
DETAIL_DIGITS = 6


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
    states = pos["state"].value_counts(normalize=True).to_dict()
    corr = ev[ev["type"].isin(CORRECTION_EVENTS)]
    determined = pos[pos["state"] != PositionState.UNDETERMINED.value]
    refused = ev[ev["type"] == EventType.FEATURE_REFUSED]
    warned = ev[ev["type"].isin([str(t) for t in WARNING_EVENTS])]
    reasons: dict[str, int] = {}
    for d in refused["detail"]:
        for r in json.loads(d).get("failed", []):
            reasons[r] = reasons.get(r, 0) + 1
    routes = determined.groupby(["line_code", "track"], dropna=True).size()
    best = routes.idxmax() if len(routes) else (None, None)
    main_route: tuple[str | None, str | None] = (best[0], best[1]) if isinstance(best, tuple) else (None, None)
    return {
        "run_id": run.run_id,
        "vehicle_id": meta.vehicle_id,
        "vehicle_kind": meta.vehicle_kind,
        "db_version": network.meta.get("db_version"),
        "config": cfg.to_dict(),
        "duration_s": float(pos["t"].iloc[-1] - pos["t"].iloc[0]) if len(pos) else 0.0,
        "distance_m": float(odo.d[-1]) if odo.d.size else 0.0,
        "line_code": main_route[0],
        "track": main_route[1],
        "first_determined_t": float(determined["t"].iloc[0]) if len(determined) else None,
        "state_share": {k: round(float(v), 6) for k, v in states.items()},
        **run_correction_stats(ev, population="balise"),
        "all_corrections": run_correction_stats(ev, population="all"),
        "n_balise_corrections": int((corr["type"] == EventType.BALISE_CORRECTION).sum()),
        "n_feature_corrections": int((corr["type"] == EventType.FEATURE_CORRECTION).sum()),
        "n_feature_refused": len(refused),
        "feature_refusals": reasons,
        "n_slips": int(ev["type"].isin(SLIP_EVENTS).sum()),
        "n_failsafe": int((ev["type"] == EventType.FAILSAFE).sum()),
        "n_anomalies": int((ev["type"] == EventType.BALISE_ANOMALY).sum()),
        "gps_decisions": len(gps.decisions) if gps else 0,
        "gps_trusted_share": float(gps.fixes["trusted"].mean()) if gps is not None and len(gps.fixes) else None,
        "max_margin_m": float(pos["margin_m"].max()) if pos["margin_m"].notna().any() else None,
        "warnings": [
            str(json.loads(d).get("message", t)) for t, d in zip(warned["type"], warned["detail"], strict=True)
        ],
        "episodes": [asdict(e) for e in odo.episodes],
        **_ground(odo, meta.wheel_diameter_m, wheel_scale),
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
