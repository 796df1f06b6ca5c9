"""The onboard positioning pipeline of SPEC §5 on a recorded run.

``run_pipeline`` wires the units: cycle preprocessing (vectorised), slip/slide odometry,
GPS analysis, the feature-point unit and the balise unit, then the solver's event loop.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.io import Run
from fieldlogs.pipeline.balise import BaliseDb, BaliseUnit
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.cycles import Cycles, build_cycles
from fieldlogs.pipeline.features import FeatureUnit
from fieldlogs.pipeline.gps import analyse_gps
from fieldlogs.pipeline.odometry import correct_odometry
from fieldlogs.pipeline.solver import solve
from fieldlogs.pipeline.truth import compare_with_truth, truth_summary
from fieldlogs.pipeline.types import Event, GpsAnalysis, Odometry
from schemas.enums import PositionState, Severity
from schemas.errors import FindingsError
from schemas.outputs import EVENTS

__all__ = ["PipelineConfig", "PipelineResult", "run_pipeline"]


@dataclass
class PipelineResult:
    run_id: str
    positions: pd.DataFrame
    events: pd.DataFrame
    summary: dict[str, Any]
    odometry: Odometry
    gps: GpsAnalysis | None = None
    kappa: np.ndarray | None = None
    truth: pd.DataFrame | None = field(default=None, repr=False)
    cycles: Cycles | None = field(default=None, repr=False)


def _clean(frame: pd.DataFrame | None, name: str, events: list[Event]) -> pd.DataFrame | None:
    """Sort by t and drop rows without t or with a repeated t (first kept), as an onboard
    unit would see the stream; every change is reported as an ``input_repaired`` event."""
    if frame is None or frame.empty:
        return frame
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    if t.size and np.isfinite(t).all() and (np.diff(t) > 0).all():
        return frame  # the normal case: nothing to repair, no copy
    n0 = len(frame)
    frame = frame[frame["t"].notna()]
    unsorted = bool((frame["t"].diff() < 0).any())
    frame = frame.sort_values("t", kind="stable")
    frame = frame[~frame["t"].duplicated(keep="first")]
    if unsorted or len(frame) != n0:
        events.append(
            Event(
                0.0,
                "input_repaired",
                detail={"stream": name, "rows_in": n0, "rows_used": len(frame), "sorted": unsorted},
            )
        )
    return frame.reset_index(drop=True)


def run_pipeline(run: Run, network: Network, cfg: PipelineConfig | None = None) -> PipelineResult:
    """Replay a run through the onboard logic; raises FindingsError when run.json is unusable."""
    cfg = cfg or PipelineConfig()
    if run.meta is None:
        raise FindingsError(
            "run.json is missing or invalid", [f for f in run.findings if f.severity == Severity.ERROR], path=run.folder
        )
    pre: list[Event] = []
    streams = {n: _clean(run.stream(n), n, pre) for n in ("tacho", "imu", "balise", "gps", "cab", "truth", "radar")}
    t_end = max((float(s["t"].iloc[-1]) for s in streams.values() if s is not None and len(s)), default=0.0)
    cycles = build_cycles(
        tacho=streams["tacho"],
        imu=streams["imu"],
        cab=streams["cab"],
        wheel_diameter_m=run.meta.wheel_diameter_m,
        teeth=run.meta.teeth,
        t_end=t_end,
        cycle_s=cfg.cycle_s,
    )
    # pulses only when the run has no IMU (correct_odometry falls back by itself)
    odo = correct_odometry(cycles, cfg.odometry, radar_on_cycles(streams["radar"], cycles.t))
    gps = analyse_gps(streams["gps"], network, cfg.gps, cycles)
    features = FeatureUnit(cycles, odo, network, cfg.feature) if cycles.has_imu and cycles.has_tacho else None
    unit = BaliseUnit(network.cached("balise_db", lambda: BaliseDb.from_network(network)), cfg.balise)
    sol = solve(cycles, odo, streams["balise"], unit, cfg, gps=gps, features=features, network=network)

    events = list(pre) + sol.events
    km = sol.positions["km_m"].to_numpy()
    for ep in odo.episodes:
        i = min(max(ep.i_start, 0), len(km) - 1) if len(km) else 0
        events.append(
            Event(
                ep.t_start,
                ep.kind,
                float(km[i]) if len(km) and np.isfinite(km[i]) else None,
                detail=ep.event_detail(),
            )
        )
    events.sort(key=lambda e: e.t)
    ev_frame = events_frame(events)
    truth = streams["truth"]
    summary = summarise(run, network, cfg, sol.positions, ev_frame, odo, gps)
    if truth is not None and len(truth):
        summary["truth"] = truth_summary(compare_with_truth(sol.positions, truth))
    kappa = getattr(features, "kappa", None)
    return PipelineResult(run.run_id, sol.positions, ev_frame, summary, odo, gps, kappa, truth, cycles)


def radar_on_cycles(radar: pd.DataFrame | None, t: np.ndarray, max_gap_s: float = 1.0) -> np.ndarray | None:
    """Radar ground speed interpolated onto the cycle times; NaN farther than ``max_gap_s``
    from a radar sample (no radar, no bridging)."""
    if radar is None or len(radar) < 2:
        return None
    tr = radar["t"].to_numpy(dtype=float)
    v = radar["speed_mps"].to_numpy(dtype=float, na_value=np.nan)
    out = np.interp(t, tr, v)
    j = np.clip(np.searchsorted(tr, t), 1, len(tr) - 1)
    gap = np.minimum(np.abs(t - tr[j - 1]), np.abs(tr[j] - t))
    return np.where(gap <= max_gap_s, out, np.nan)


def events_frame(events: list[Event]) -> pd.DataFrame:
    rows = [
        {
            "t": e.t,
            "type": e.type,
            "km_m": e.km_m,
            "correction_m": e.correction_m,
            "correction_pct": e.correction_pct,
            "detail": json.dumps(e.detail, ensure_ascii=False, default=_json_default, sort_keys=True),
        }
        for e in events
    ]
    frame = pd.DataFrame(rows, columns=EVENTS.column_names)
    for c in ("t", "km_m", "correction_m", "correction_pct"):
        frame[c] = pd.to_numeric(frame[c]).astype("float64")
    for c in ("type", "detail"):
        frame[c] = frame[c].astype("string")
    return frame


def _json_default(v: Any) -> Any:
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating,)):
        return None if not np.isfinite(v) else round(float(v), 6)
    if isinstance(v, np.bool_):
        return bool(v)
    return str(v)


def summarise(
    run: Run,
    network: Network,
    cfg: PipelineConfig,
    pos: pd.DataFrame,
    ev: pd.DataFrame,
    odo: Odometry,
    gps: GpsAnalysis | None,
) -> dict[str, Any]:
    """Headline figures of one run (what audits aggregate)."""
    meta = run.meta
    assert meta is not None
    states = pos["state"].value_counts(normalize=True).to_dict()
    corr = ev[ev["type"].isin(["balise_correction", "feature_correction"])]
    pct = corr["correction_pct"].dropna()
    determined = pos[pos["state"] != PositionState.UNDETERMINED.value]
    refused = ev[ev["type"] == "feature_refused"]
    reasons: dict[str, int] = {}
    for d in refused["detail"]:
        for r in json.loads(d).get("failed", []):
            reasons[r] = reasons.get(r, 0) + 1
    routes = determined.groupby(["line_code", "track"], dropna=True).size()
    main_route = routes.idxmax() if len(routes) else (None, None)
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
        "n_corrections": len(corr),
        "n_balise_corrections": int((corr["type"] == "balise_correction").sum()),
        "n_feature_corrections": int((corr["type"] == "feature_correction").sum()),
        "n_feature_refused": len(refused),
        "feature_refusals": reasons,
        "mean_correction_pct": float(pct.mean()) if len(pct) else None,
        "max_correction_pct": float(pct.max()) if len(pct) else None,
        "n_slips": int(ev["type"].isin(["slip", "slide"]).sum()),
        "n_failsafe": int((ev["type"] == "failsafe").sum()),
        "n_anomalies": int((ev["type"] == "balise_anomaly").sum()),
        "gps_decisions": len(gps.decisions) if gps else 0,
        "gps_trusted_share": float(gps.fixes["trusted"].mean()) if gps is not None and len(gps.fixes) else None,
        "max_margin_m": float(pos["margin_m"].max()) if pos["margin_m"].notna().any() else None,
        "episodes": [asdict(e) for e in odo.episodes],
    }
