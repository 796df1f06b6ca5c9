"""Road-rail runs paired with possession plans, with deliberate mistakes (tests, bench).

``make_case(network, kind, seed)`` draws a possession (line, track, 400–800 m section), a
level crossing inside it where the vehicle goes on rail from a road position beside the
track, work movements back and forth inside the section at 10–20 km/h, and the plan's
times around the run; then simulates the run (``fieldlogs.simulate``) and states which
alarms the plan and the run must give (``expected``). Kinds:

* ``correct`` — everything as planned: no alarm;
* ``wrong_track`` — the vehicle goes on rail on the other track of the line;
* ``overrun`` — one work movement runs 10–50 m past an end of the section;
* ``early_release`` — the plan's ``released_at`` falls while the vehicle is on rail;
* ``not_started`` — on rail before ``started_at`` (started late, or never).

``poor_sky=True`` adds a 60–200 m poor-sky stretch inside the section (multipath, fix 1,
extra noise: ``gps.poor_sky_*``); with ``poor_sky_ends=True`` the poor sky straddles both
section ends instead (30–100 m inside to 60 m beyond: the hardest case for the overrun
alarm and for a vehicle working close to an end); ``tacho`` adds a tachometer stream. About half the cases
carry decoy possessions that must not be matched (another night; the other track far away).
Everything is drawn from ``np.random.default_rng(seed)``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.possession.plan import Possession, plan_frame
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.typed import LogFormat
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import Scenario, scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.enums import AlarmType

KINDS = ("correct", "wrong_track", "overrun", "early_release", "not_started")
#: Wall-clock time of the earliest run start (runs start up to 2 h later).
BASE_TIME = "2026-01-16T00:30:00+09:00"
#: Alarm each mistake must give.
EXPECTED_ALARM: dict[str, AlarmType] = {
    "wrong_track": AlarmType.WRONG_TRACK,
    "overrun": AlarmType.OVERRUN,
    "early_release": AlarmType.RELEASED_ON_RAIL,
    "not_started": AlarmType.NOT_STARTED,
}
#: Alarm types that report each mistake (a wrong track may first be *suspected* at the
#: decision target, before the evidence decides it).
MISTAKE_ALARMS: dict[str, tuple[AlarmType, ...]] = {kind: (typ,) for kind, typ in EXPECTED_ALARM.items()} | {
    "wrong_track": (AlarmType.WRONG_TRACK, AlarmType.WRONG_TRACK_SUSPECTED)
}


@dataclass
class PossessionCase:
    name: str
    kind: str
    seed: int
    poor_sky: bool
    scenario: Scenario
    streams: dict[str, pd.DataFrame]
    meta: RunMeta
    possessions: list[Possession]
    work_no: str
    line_code: str
    plan_track: str
    run_track: str
    km_from_m: float
    km_to_m: float
    t_on: float
    t_off: float
    expected: list[dict[str, Any]] = field(default_factory=list)
    """``{"type", "t_true"}`` per alarm the case must give (t_true: the true event time [s])."""

    def write(self, folder: Path, fmt: LogFormat = "parquet", force: bool = False) -> tuple[Path, Path]:
        """Write ``folder/<name>/`` (the run) and ``folder/<name>.csv`` (its plan)."""
        folder = Path(folder)
        run_dir = write_run(folder / self.name, self.meta, self.streams, fmt=fmt, force=force)
        plan = folder / f"{self.name}.csv"
        plan_frame(self.possessions).to_csv(plan, index=False, lineterminator="\n")
        return run_dir, plan


def _tracks(network: Network, line: str) -> dict[str, tuple[float, float]]:
    g = network.gis[network.gis["line_code"].astype(str) == line]
    return {str(t): (float(s["km_m"].min()), float(s["km_m"].max())) for t, s in g.groupby("track")}


def _minute(t: datetime) -> datetime:
    return t.replace(second=0, microsecond=0)


def _section(rng: np.random.Generator, tracks: dict[str, tuple[float, float]]) -> tuple[float, float, float, float]:
    """(km_from, km_to) of a 400–800 m section 300 m inside every track's grid, and those limits."""
    lo = max(a for a, _ in tracks.values()) + 300.0
    hi = min(b for _, b in tracks.values()) - 300.0
    length = float(rng.uniform(400.0, 800.0))
    km_from = float(np.round(rng.uniform(lo, hi - length), -1))
    km_to = km_from + float(np.round(length, -1))
    return km_from, km_to, lo, hi


def _work_path(rng: np.random.Generator, kind: str, km_from: float, km_to: float) -> list[float]:
    """Turning points of the work movements: mostly to 25–60 m from an end, an overrun's one
    10–50 m beyond it."""
    km_on = float(rng.uniform(km_from + 40.0, km_to - 40.0))
    n_turns = int(rng.integers(2, 5))
    high = bool(rng.random() < 0.5)
    path = [km_on]
    for _ in range(n_turns):
        if rng.random() < 0.75:
            inner = float(rng.uniform(25.0, 60.0))
            path.append(km_to - inner if high else km_from + inner)
            high = not high
        else:
            path.append(float(rng.uniform(km_from + 60.0, km_to - 60.0)))
    path.append(float(rng.uniform(km_from + 40.0, km_to - 40.0)))
    if kind == "overrun":
        i = int(rng.integers(1, len(path) - 1))
        beyond = float(rng.uniform(10.0, 50.0))
        path[i] = km_to + beyond if path[i] > 0.5 * (km_from + km_to) else km_from - beyond
    return [path[0]] + [b for a, b in itertools.pairwise(path) if abs(b - a) > 5.0]


def _poor_sky(
    rng: np.random.Generator, km_from: float, km_to: float, poor_sky: bool, ends: bool
) -> dict[str, Any] | None:
    """The scenario's ``gps`` section: a poor-sky stretch inside the section, or at both ends."""
    if poor_sky and ends:
        return {
            "poor_sky_km_m": [
                [km_from - 60.0, km_from + float(rng.uniform(30.0, 100.0))],
                [km_to - float(rng.uniform(30.0, 100.0)), km_to + 60.0],
            ]
        }
    if poor_sky:
        a = float(rng.uniform(km_from, km_to - 60.0))
        return {"poor_sky_km_m": [[a, min(a + float(rng.uniform(60.0, 200.0)), km_to)]]}
    return None


def _scenario(
    rng: np.random.Generator, kind: str, seed: int, route: dict[str, Any], start: datetime, tacho: bool
) -> dict[str, Any]:
    """The road-rail scenario of a case (``fieldlogs.simulate`` settings)."""
    return {
        "name": f"possession case {kind} {seed}",
        "run": {
            "run_id": f"PZ-{kind}-{seed}",
            "vehicle_id": f"RR-{seed % 7 + 1:02d}",
            "vehicle_kind": "road_rail",
            "start_time": start.isoformat(),
        },
        "route": route,
        "running": {
            "line_speed_kmh": float(rng.uniform(10.0, 20.0)),
            "accel_kmh_s": 1.5,
            "brake_kmh_s": 2.0,
            "dwell_s": float(rng.uniform(15.0, 40.0)),
            "reversal_dwell_s": float(rng.uniform(20.0, 60.0)),
        },
        "road_rail": {
            "off_rail_before_s": float(rng.uniform(60.0, 120.0)),
            "off_rail_after_s": 60.0,
            "road_offset_m": float(rng.choice([-1.0, 1.0]) * rng.uniform(6.0, 15.0)),
            "transfer_s": float(rng.uniform(15.0, 30.0)),
        },
        "sensors": {"imu": False, "tacho": tacho, "gps": True, "balise": False, "radar": False, "truth": True},
        "slip": {"slips": 0, "slides": 0},
    }


def _on_rail(cab: pd.DataFrame) -> tuple[float, float]:
    """(t_on, t_off) of the simulated run's on-rail period."""
    t = cab["t"].to_numpy()
    pto = cab["pto"].to_numpy(dtype=float, na_value=0.0)
    t_on = float(t[np.flatnonzero(pto > 0)[0]])
    return t_on, float(t[np.flatnonzero((pto < 1) & (t > t_on))[0]])


@dataclass
class _PlanTimes:
    planned_start: datetime
    planned_end: datetime
    started_at: datetime | None
    released_at: datetime | None


def _plan_times(rng: np.random.Generator, start: datetime, off_wall: datetime) -> _PlanTimes:
    """Planned and actual times around a correct run."""
    planned_start = _minute(start - timedelta(minutes=float(rng.uniform(5.0, 30.0))))
    planned_end = _minute(off_wall + timedelta(minutes=float(rng.uniform(10.0, 40.0))))
    started_at = _minute(start - timedelta(minutes=float(rng.uniform(1.0, 10.0))))
    released_at = _minute(off_wall + timedelta(minutes=float(rng.uniform(2.0, 15.0))))
    return _PlanTimes(planned_start, planned_end, started_at, released_at)


def _mistake(
    rng: np.random.Generator,
    kind: str,
    times: _PlanTimes,
    start: datetime,
    on_rail: tuple[float, float],
    streams: dict[str, pd.DataFrame],
    section: tuple[float, float],
) -> list[dict[str, Any]]:
    """Put the case's mistake into the plan times; the alarm it must give, with its true time."""
    t_on, t_off = on_rail
    on_wall = start + timedelta(seconds=t_on)
    if kind == "not_started":
        if rng.random() < 0.5:
            times.started_at = None
        else:
            late = timedelta(seconds=float(rng.uniform(30.0, 0.5 * (t_off - t_on))))
            times.started_at = (on_wall + late).replace(microsecond=0)
        return [{"type": EXPECTED_ALARM[kind], "t_true": t_on}]
    if kind == "early_release":
        early = timedelta(seconds=float(rng.uniform(0.3, 0.8) * (t_off - t_on)))
        times.released_at = (on_wall + early).replace(microsecond=0)
        return [{"type": EXPECTED_ALARM[kind], "t_true": (times.released_at - start).total_seconds()}]
    if kind == "wrong_track":
        return [{"type": EXPECTED_ALARM[kind], "t_true": t_on}]
    if kind == "overrun":
        truth = streams["truth"]
        km = truth["km_m"].to_numpy(dtype=float, na_value=np.nan)
        out = np.flatnonzero((km > section[1]) | (km < section[0]))
        return [{"type": EXPECTED_ALARM[kind], "t_true": float(truth["t"].to_numpy()[out[0]])}]
    return []


def _plan(
    rng: np.random.Generator,
    work: str,
    line: str,
    tracks: tuple[str, list[str]],
    section: tuple[float, float, float, float],
    times: _PlanTimes,
) -> list[Possession]:
    """The case's possession, and in about half the cases decoys that must not be matched:
    the same section another night, and the other track far away."""
    plan_track, others = tracks
    km_from, km_to, lo, hi = section
    t = times
    possessions = [
        Possession(work, line, plan_track, km_from, km_to, t.planned_start, t.planned_end, t.started_at, t.released_at)
    ]
    if rng.random() < 0.5:
        day = timedelta(days=1)
        possessions.append(
            Possession(f"{work}-N", line, plan_track, km_from, km_to, t.planned_start + day, t.planned_end + day, None)
        )
        far = km_to + 1500.0 if km_to + 2000.0 < hi else km_from - 2000.0
        if others and far > lo:
            possessions.append(
                Possession(
                    f"{work}-A",
                    line,
                    others[0],
                    far,
                    far + 500.0,
                    t.planned_start,
                    t.planned_end,
                    t.started_at,
                    t.released_at,
                )
            )
    return possessions


def make_case(
    network: Network,
    kind: str,
    seed: int,
    *,
    poor_sky: bool = False,
    poor_sky_ends: bool = False,
    tacho: bool = False,
    line_code: str | None = None,
) -> PossessionCase:
    """One (run, plan) pair; see the module docstring."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}")
    rng = np.random.default_rng(seed)
    line = line_code or sorted(set(network.gis["line_code"].astype(str)))[0]
    tracks = _tracks(network, line)
    names = sorted(tracks)
    plan_track = str(rng.choice(names))
    others = [t for t in names if t != plan_track]
    run_track = others[0] if kind == "wrong_track" and others else plan_track
    section = _section(rng, tracks)
    km_from, km_to = section[0], section[1]
    path = _work_path(rng, kind, km_from, km_to)
    start = datetime.fromisoformat(BASE_TIME) + timedelta(minutes=int(rng.integers(0, 120)))
    route = {"line_code": line, "track": run_track, "path_km_m": path, "start_cab": "F"}
    over = _scenario(rng, kind, seed, route, start, tacho)
    gps = _poor_sky(rng, km_from, km_to, poor_sky, poor_sky_ends)
    if gps is not None:
        over["gps"] = gps
    scenario = scenario_from_dict(over, source=f"possession case {kind} {seed}")
    streams, meta = simulate_run(network, scenario, seed=seed)
    t_on, t_off = _on_rail(streams["cab"])
    times = _plan_times(rng, start, start + timedelta(seconds=t_off))
    expected = _mistake(rng, kind, times, start, (t_on, t_off), streams, (km_from, km_to))
    work = f"W{seed:05d}"
    return PossessionCase(
        name=f"pz-{kind}-{seed}{'-poor' if poor_sky else ''}",
        kind=kind,
        seed=seed,
        poor_sky=poor_sky,
        scenario=scenario,
        streams=streams,
        meta=meta,
        possessions=_plan(rng, work, line, (plan_track, others), section, times),
        work_no=work,
        line_code=line,
        plan_track=plan_track,
        run_track=run_track,
        km_from_m=km_from,
        km_to_m=km_to,
        t_on=t_on,
        t_off=t_off,
        expected=expected,
    )


def make_cases(
    network: Network,
    n: int,
    seed0: int = 1000,
    *,
    poor_sky_every: int = 3,
    poor_sky_ends: bool = False,
    tacho_every: int = 0,
) -> list[PossessionCase]:
    """``n`` cases cycling through the kinds (every ``poor_sky_every``-th round of kinds with
    poor sky, at the section ends with ``poor_sky_ends``; every ``tacho_every``-th case with a
    tachometer; 0 = never)."""
    out = []
    for i in range(n):
        kind = KINDS[i % len(KINDS)]
        poor = poor_sky_every > 0 and (i // len(KINDS)) % poor_sky_every == poor_sky_every - 1
        tacho = tacho_every > 0 and i % tacho_every == 0
        out.append(make_case(network, kind, seed0 + i, poor_sky=poor, poor_sky_ends=poor_sky_ends, tacho=tacho))
    return out
