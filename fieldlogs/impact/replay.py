"""``db impact``, the per-run part: one run replayed against two DB versions.

The worker (:func:`impact_one`) reads a run once and runs the positioning pipeline
(:func:`fieldlogs.pipeline.run.run_pipeline`) against the old and the new DB — and, for a
road-rail run when a possession plan is given, the possession check against each — and
returns per version only what the report needs (:class:`RunFigures`, plain data, small to
pickle). Both DBs stay loaded in each worker process (:func:`load_pair`): the replayer's
own cache (:mod:`fieldlogs.replay.network`) holds one DB per process and would read them
in turn for every run. Two DBs with the same content are replayed once.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.database import read_network
from dbtools.network import Network, content_hash, network_content_hash
from fieldlogs.pipeline.corrections import run_correction_stats
from fieldlogs.replay.network import DbRef
from schemas.enums import EventType, VehicleKind
from schemas.errors import InputError

#: Events whose changes between the versions are listed one by one.
LISTED_EVENTS = (EventType.BALISE_CORRECTION, EventType.FEATURE_CORRECTION)
#: Identifier of the DB row behind an event, from its detail (first key present).
ROW_KEYS = ("balise_id", "feature_id", "id")

_PAIR: dict[tuple[tuple[str, str], tuple[str, str]], tuple[Network, Network]] = {}
_PLANS: dict[tuple[str, tuple[str, str]], Any] = {}


def _load(ref: DbRef) -> Network:
    net = read_network(Path(ref.path), verify=False)  # checked against the reference instead
    actual = content_hash(net.tables)
    if actual != ref.content_hash:
        raise InputError(
            f"the DB changed while the runs were replayed (content hash {actual[:12]}, "
            f"expected {ref.content_hash[:12]})",
            path=ref.path,
        )
    return net


def open_pair(old: Path, new: Path) -> tuple[DbRef, DbRef, Network, Network]:
    """Read both DBs in this process (InputError when unreadable), hash their content and
    keep them for the runs replayed here."""
    nets = []
    refs = []
    for p in (old, new):
        path = Path(p).resolve()
        net = read_network(path)  # verified (dbtools.integrity)
        refs.append(DbRef(str(path), network_content_hash(net)))
        nets.append(net)
    _PAIR.clear()
    _PAIR[(refs[0].key, refs[1].key)] = (nets[0], nets[1])
    return refs[0], refs[1], nets[0], nets[1]


def load_pair(old: DbRef, new: DbRef) -> tuple[Network, Network]:
    """Both DBs of a replay, read once per process."""
    key = (old.key, new.key)
    pair = _PAIR.get(key)
    if pair is None:
        a = _load(old)
        b = a if new.key == old.key else _load(new)
        _PAIR.clear()
        pair = _PAIR[key] = (a, b)
    return pair


def _plan(path: str, ref: DbRef, network: Network) -> Any:
    """The possession plan read against one DB version (its km checked on that DB), once per process."""
    from fieldlogs.possession.plan import load_plan

    key = (path, ref.key)
    if key not in _PLANS:
        _PLANS[key] = load_plan(Path(path), network)
    return _PLANS[key]


@dataclass
class RunFigures:
    """What one DB version gave on one run (plain data)."""

    ok: bool
    error: str | None = None
    summary: dict[str, Any] = field(default_factory=dict)
    """run_id, vehicle, route, direction, balise / feature / all correction statistics,
    refusals by diagnostic, anomalies, fail-safes, slips, max margin, state shares."""
    corrections: list[dict[str, Any]] = field(default_factory=list)
    """Balise and feature corrections: t, type, row (balise or feature id), km, amount, %."""
    alarms: dict[str, int] | None = None
    """Possession alarms by type (road-rail runs with a plan), else None."""


def _row_id(detail: str | None) -> str:
    if not detail:
        return ""
    try:
        d = json.loads(detail)
    except (TypeError, ValueError):
        return ""
    return next((str(d[k]) for k in ROW_KEYS if k in d and d[k] is not None), "")


def corrections_of(events: pd.DataFrame) -> list[dict[str, Any]]:
    """The balise and feature corrections of an events frame, one dict each."""
    ev = events[events["type"].isin([str(t) for t in LISTED_EVENTS])]
    out = []
    for t, typ, km, amount, pct, detail in zip(
        ev["t"], ev["type"], ev["km_m"], ev["correction_m"], ev["correction_pct"], ev["detail"], strict=True
    ):
        out.append(
            {
                "t": round(float(t), 3),
                "type": str(typ),
                "row": _row_id(None if pd.isna(detail) else str(detail)),
                "km_m": _num(km),
                "correction_m": _num(amount),
                "correction_pct": _num(pct),
            }
        )
    return out


def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if np.isfinite(f) else None


def _direction(pos: pd.DataFrame) -> str | None:
    km = pos["km_m"].dropna()
    if len(km) < 2:
        return None
    return "down" if float(km.iloc[-1]) >= float(km.iloc[0]) else "up"


def figures_of(result: Any) -> RunFigures:
    """The figures of one pipeline result."""
    s = result.summary
    ev = result.events
    feature = ev[ev["type"] == str(EventType.FEATURE_CORRECTION)]
    summary = {
        **{k: s.get(k) for k in ("run_id", "vehicle_id", "vehicle_kind", "db_version", "line_code", "track")},
        "direction": _direction(result.positions),
        "balise": run_correction_stats(ev, population="balise"),
        "feature": run_correction_stats(feature, population="all"),
        "all": run_correction_stats(ev, population="all"),
        **{
            k: s.get(k)
            for k in (
                "n_feature_refused",
                "feature_refusals",
                "n_anomalies",
                "n_failsafe",
                "n_slips",
                "max_margin_m",
                "first_determined_t",
                "distance_m",
            )
        },
    }
    return RunFigures(True, summary=summary, corrections=corrections_of(ev))


def _alarms(run: Any, network: Network, plan_path: str | None, ref: DbRef, tree: Any) -> dict[str, int] | None:
    """Possession alarms by type of a road-rail run checked against the plan on this DB."""
    if plan_path is None or run.meta is None or run.meta.vehicle_kind != VehicleKind.ROAD_RAIL:
        return None
    from fieldlogs.possession.check import check_run

    plan = _plan(plan_path, ref, network)
    check = check_run(run, network, plan.possessions, tree.gps, tree.possession)
    counts: dict[str, int] = {}
    for a in check.alarms:
        counts[a.type.value] = counts.get(a.type.value, 0) + 1
    return counts


def _one_version(run: Any, network: Network, ref: DbRef, plan_path: str | None, tree: Any) -> RunFigures:
    """Pipeline (and possession check) of one run on one DB version; an error becomes the figures' message."""
    from fieldlogs.pipeline.run import run_pipeline  # refuses a run it cannot position honestly
    from fieldlogs.replay.tasks import error_message

    try:
        figs = figures_of(run_pipeline(run, network, tree.pipeline))
        figs.alarms = _alarms(run, network, plan_path, ref, tree)
        return figs
    except Exception as exc:  # one version failing on a run is a finding of the report
        return RunFigures(False, error=error_message(exc))


def impact_one(run_path: str, old: DbRef, new: DbRef, plan_path: str | None, tree: Any) -> dict[str, Any]:
    """Replayer worker: one run, read once, against both DB versions:
    ``{"run": path, "old": RunFigures, "new": RunFigures}``."""
    from fieldlogs.runs.handle import read_run

    net_old, net_new = load_pair(old, new)
    run = read_run(Path(run_path))
    a = _one_version(run, net_old, old, plan_path, tree)
    b = a if new.key == old.key else _one_version(run, net_new, new, plan_path, tree)
    return {"run": run_path, "old": a, "new": b}
