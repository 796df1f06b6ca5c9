"""One positioning unit per cab, working independently [S003 §2]: 車載装置は各運転台に設置し，
独立して動作する — an onboard unit in each driving cab. On a turnback (a terminus, a loop) the
driver changes cabs and the other unit becomes the one in charge; both carry on all the time.

**Unit F** is the pipeline as it always runs: its forward is the vehicle's F end. **Unit R**
sees the same run from the R cab: its body frame is the vehicle's turned half round about z
(x_R = −x, y_R = −y, z_R = z), so

* the IMU's ax, ay, wx, wy change sign (az, wz do not);
* the cab's F and R swap (its forward is its own cab), a two-phase tacho's ``direction``
  changes sign, and so does the truth's ``speed_mps`` (toward the unit's forward end);
* run.json's vehicle geometry has every ``x_m`` and ``y_m`` negated (the reader, antennas and
  IMU seen from the other end) and a radar ``looks_toward`` F ↔ R;
* on a vehicle with a balise reader in each cab (the balise stream's ``reader`` column, run.json
  vehicle ``balise_reader`` and ``balise_reader_r``) the readers swap too: each unit reads its
  own cab's reader, "F" in its own frame (:func:`fieldlogs.pipeline.run.own_reader`).

**Each cab's own sensors.** A run recorded with the R cab's own IMU, tacho and GPS (the
streams ``imu_r``, ``tacho_r``, ``gps_r``, :data:`schemas.logs.CAB_R_STREAMS`, already in the R
cab's frame; the simulator's ``[cab_r]``) gives unit R those streams as its ``imu``, ``tacho``
and ``gps``, as they are: the two units then work from independent sensors. Its geometry is the
vehicle block's ``gps_antenna_r`` and ``imu_r`` (swapped with ``gps_antenna`` and ``imu``
before the mirror above; a run without ``gps_antenna_r`` has the R antenna at the reference
point, :data:`R_DEFAULT`), its truth's ``slipping`` the R axle's ``slipping_r``, its wheel run.json's nominal one.
A stream without its R counterpart falls back to the turned view of the F one (and so do the
shared sensors: balise readers as above, radar); ``units.json`` says which stream unit R read
(``unit_r``: :func:`r_sources`).

Both units position the vehicle's **reference point** (run.json ``vehicle``), so the known
distance between their positions along the track is 0 (each cab end lies its ``x_m`` from it).
:func:`compare_units` puts the two outputs side by side per cycle: where both claim a km, the
difference d = km_F − km_R must lie within the sum of their margins, |d| ≤ m_F + m_R (each
unit's error within its margin implies it), and where both are *determined* their track ids
must agree. A cycle breaking either is a **disagreement**: one of the units is wrong beyond
what it claims, and the summary names the spans.

``trainpos run --unit both`` (:func:`replay_units`) writes each unit's outputs into ``OUT/F``
and ``OUT/R`` and the comparison's summary into ``OUT/units.json``; each span of disagreement
is also a ``units_disagree`` event in both units' events (:func:`disagreement_events`).
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.atomic import atomic_folder
from dbtools.masks import true_runs
from dbtools.network import Network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.outputs import ResultsWriter
from fieldlogs.pipeline.windows import Replayed, replay_bounded
from fieldlogs.runs.handle import Run, read_run
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.write import write_run
from schemas.enums import CabDirection, EventType, PositionState
from schemas.logs import CAB_R_STREAMS

UNITS = ("F", "R")
"""The positioning units, named after their cab."""
MIRRORED_IMU = ("ax", "ay", "wx", "wy")
"""IMU columns whose sign changes in the other cab's frame (a half turn about z)."""
SWAP = {CabDirection.FORWARD.value: CabDirection.REVERSE.value, CabDirection.REVERSE.value: CabDirection.FORWARD.value}


def _negated(frame: pd.DataFrame, columns: tuple[str, ...]) -> pd.DataFrame:
    out = frame.copy()
    for c in columns:
        if c in out.columns:
            out[c] = -out[c] + 0  # + 0: no negative zeros
    return out


def mirrored_streams(streams: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """The run's streams as unit R records them (see the module docstring)."""
    out = dict(streams)
    if "imu" in out:
        out["imu"] = _negated(out["imu"], MIRRORED_IMU)
    if "tacho" in out:
        out["tacho"] = _negated(out["tacho"], ("direction",))
    if "truth" in out:
        out["truth"] = _negated(out["truth"], ("speed_mps",))
    for name, column in (("cab", "direction"), ("balise", "reader")):
        if name in out and column in out[name].columns:
            frame = out[name].copy()
            frame[column] = frame[column].astype("string").map(SWAP, na_action="ignore").astype("string")
            out[name] = frame
    return out


def mirrored_block(value: Any) -> Any:
    """A run.json block with every ``x_m``/``y_m`` negated and a ``looks_toward`` swapped."""
    if isinstance(value, dict):
        return {
            k: (-v if k in ("x_m", "y_m") and isinstance(v, int | float) and not isinstance(v, bool) else
                SWAP.get(v, v) if k == "looks_toward" and isinstance(v, str) else mirrored_block(v))
            for k, v in value.items()
        }  # fmt: skip
    if isinstance(value, list):
        return [mirrored_block(v) for v in value]
    return value


#: Where unit R's own sensor is when run.json's vehicle block does not say (``<section>_r``
#: absent): the GPS antenna at the reference point; the IMU's lever arm is not used.
R_DEFAULT: dict[str, dict[str, float] | None] = {"gps_antenna": {"x_m": 0.0, "y_m": 0.0}, "imu": None}


def _swapped(vehicle: dict[str, Any], section: str, own: bool) -> dict[str, Any]:
    """``vehicle`` with ``section`` and ``section_r`` swapped: the R cab's is unit R's own (with its
    own stream, ``own``, an absent R section is :data:`R_DEFAULT`)."""
    other = f"{section}_r"
    if other not in vehicle and not own:
        return vehicle
    out = {k: v for k, v in vehicle.items() if k not in (section, other)}
    mine = vehicle.get(other, R_DEFAULT.get(section))
    if mine is not None:
        out[section] = mine
    if section in vehicle:
        out[other] = vehicle[section]
    return out


def mirrored_meta(meta: RunMeta, own: Iterable[str] = ()) -> RunMeta:
    """run.json as unit R sees it: its own reader (and, for the F streams ``own`` it has its own
    of, its own GPS antenna and IMU), every x/y negated (:func:`mirrored_block`)."""
    from dataclasses import replace

    extra = dict(meta.extra)
    if "radar" in extra:
        extra["radar"] = mirrored_block(extra["radar"])
    vehicle = meta.vehicle
    if vehicle is not None:
        vehicle = _swapped(vehicle, "balise_reader", False)
        for stream, section in (("gps", "gps_antenna"), ("imu", "imu")):
            vehicle = _swapped(vehicle, section, True) if stream in own else vehicle
    return replace(meta, vehicle=mirrored_block(vehicle), extra=extra)


def r_sources(run: Run) -> dict[str, str]:
    """Per sensor stream unit R needs, the run's stream it reads: the R cab's own (``imu_r``…)
    where the run has it, else the F stream turned round (``imu``…)."""
    return {
        f: r if run.has(r) else f for f, r in CAB_R_STREAMS.items() if run.has(r) or run.has(f)
    }  # fmt: skip


def r_view(sources: dict[str, str]) -> str:
    """How unit R saw the run, in words (``units.json`` ``unit_r.view``)."""
    own = [f for f, r in sources.items() if r != f]
    if not own:
        return "the F cab's streams turned round (the run has no R cab streams)"
    turned = [f for f in sources if f not in own]
    return (
        "the R cab's own "
        + ", ".join(sources[f] for f in own)
        + (f"; turned round: {', '.join(turned)}" if turned else "")
    )


def unit_run(run: Run, unit: str, folder: Path) -> Run:
    """The run as unit ``unit`` records it: ``run`` itself for F; for R, written to ``folder``
    (a scratch folder the caller owns), the R cab's own streams where the run has them and the
    mirror of the others (module docstring)."""
    if unit == "F":
        return run
    if run.meta is None:
        return run  # unusable: the pipeline refuses it with its own message
    own = {f: r for f, r in r_sources(run).items() if r != f}
    skip = set(own) | set(CAB_R_STREAMS.values())
    streams = {n: frame for n in run.streams_present() if n not in skip and (frame := run.stream(n)) is not None}
    view = mirrored_streams(streams)
    view.update({f: frame for f, r in own.items() if (frame := run.stream(r)) is not None})
    truth = view.get("truth")
    if truth is not None and "slipping_r" in truth.columns:  # unit R's wheel is the R axle
        view["truth"] = truth.drop(columns="slipping_r")
        if "tacho" in own:
            view["truth"]["slipping"] = truth["slipping_r"]
    return read_run(write_run(folder, mirrored_meta(run.meta, own), view, force=True))


def compare_units(pos_f: pd.DataFrame, pos_r: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Per cycle the two units' km, margins and difference, and the disagreement summary."""
    m = pd.merge(pos_f, pos_r, on="t", suffixes=("_f", "_r"))
    km_f, km_r = (m[f"km_m_{u}"].to_numpy(dtype=float, na_value=np.nan) for u in "fr")
    mg_f, mg_r = (m[f"margin_m_{u}"].to_numpy(dtype=float, na_value=np.nan) for u in "fr")
    st_f, st_r = (m[f"state_{u}"].to_numpy(dtype=object) for u in "fr")
    claimed = (st_f != PositionState.UNDETERMINED.value) & (st_r != PositionState.UNDETERMINED.value)
    both = claimed & np.isfinite(km_f) & np.isfinite(km_r)
    diff = np.where(both, km_f - km_r, np.nan)
    bound = mg_f + mg_r
    beyond = both & (np.abs(np.nan_to_num(diff)) > bound)
    det = (st_f == PositionState.DETERMINED.value) & (st_r == PositionState.DETERMINED.value)
    tr_f, tr_r = (m[f"track_id_{u}"].astype("string").fillna("").to_numpy(dtype=object) for u in "fr")
    other_track = det & (tr_f != tr_r)
    frame = pd.DataFrame(
        {
            "t": m["t"].to_numpy(dtype=float),
            "km_f_m": km_f,
            "km_r_m": km_r,
            "difference_m": diff,
            "bound_m": np.where(both, bound, np.nan),
            "track_f": tr_f,
            "track_r": tr_r,
            "beyond_margins": beyond,
            "other_track": other_track,
            "disagree": beyond | other_track,
        }
    )
    t = frame["t"].to_numpy()
    spans = [[float(t[a]), float(t[b - 1])] for a, b in _spans(frame["disagree"].to_numpy(dtype=bool))]
    sized = both & (bound > 0)  # the share of a zero bound (both margins 0) is not a number
    with np.errstate(over="ignore"):  # a subnormal bound: the share is inf, and says so
        shares = np.abs(diff[sized]) / bound[sized]
    summary = {
        "cycles": len(frame),
        "cycles_compared": int(both.sum()),
        "max_abs_difference_m": float(np.nanmax(np.abs(diff))) if both.any() else None,
        "max_difference_share_of_bound": float(np.max(shares)) if sized.any() else None,
        "cycles_beyond_margins": int(beyond.sum()),
        "cycles_on_other_tracks": int(other_track.sum()),
        "disagreements": spans,
    }
    return frame, summary


def _spans(bad: np.ndarray) -> list[tuple[int, int]]:
    """(first, end exclusive) of every run of True."""
    starts, ends = true_runs(bad)
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def disagreement_events(frame: pd.DataFrame, unit: str) -> pd.DataFrame:
    """One ``units_disagree`` event per span of disagreement of :func:`compare_units`' ``frame``,
    as unit ``unit`` records it: at the span's first cycle, its own km there; ``detail`` the
    other unit, the span's end ``t_to``, its cycles beyond the margins and on other tracks, and
    at its worst cycle (``t_worst``, :func:`_worst`) the difference own − other, the bound
    m_F + m_R, both units' km and their tracks (``track_id``, ``other_track_id``)."""
    from fieldlogs.pipeline.summary import events_frame
    from fieldlogs.pipeline.types import Event

    own, other = ("f", "r") if unit == "F" else ("r", "f")
    sign = 1.0 if unit == "F" else -1.0
    events = []
    for a, b in _spans(frame["disagree"].to_numpy(dtype=bool)):
        span = frame.iloc[a:b]
        w = span.iloc[_worst(span)]
        detail = {
            "other_unit": "R" if unit == "F" else "F",
            "t_to": float(span["t"].iloc[-1]),
            "cycles": len(span),
            "cycles_beyond_margins": int(span["beyond_margins"].sum()),
            "cycles_on_other_tracks": int(span["other_track"].sum()),
            "t_worst": float(w["t"]),
            "difference_m": _num(sign * w["difference_m"]),
            "bound_m": _num(w["bound_m"]),
            "km_at_worst_m": _num(w[f"km_{own}_m"]),
            "other_km_at_worst_m": _num(w[f"km_{other}_m"]),
            "track_id": str(w[f"track_{own}"]) or None,
            "other_track_id": str(w[f"track_{other}"]) or None,
        }
        km = span[f"km_{own}_m"].iloc[0]
        events.append(Event(float(span["t"].iloc[0]), EventType.UNITS_DISAGREE, _num(km), detail=detail))
    return events_frame(events)


def _worst(span: pd.DataFrame) -> int:
    """The span's worst cycle: the largest share |d| / (m_F + m_R) of the bound — a cycle beyond
    the margins where the span has one, as ``max_difference_share_of_bound`` measures — else the
    largest |d|, else the first."""
    d = span["difference_m"].abs().to_numpy(dtype=float)
    bound = span["bound_m"].to_numpy(dtype=float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        share = np.where(np.isfinite(d) & (bound > 0), d / bound, np.nan)
    if np.isfinite(share).any():
        return int(np.nanargmax(share))
    return int(np.nanargmax(d)) if np.isfinite(d).any() else 0


def _num(v: Any) -> float | None:
    return float(v) if v is not None and np.isfinite(v) else None


def with_events(events: pd.DataFrame, more: pd.DataFrame) -> pd.DataFrame:
    """``events`` and ``more`` in one frame in time order (stable: equal times keep their order)."""
    if more.empty:
        return events
    both = pd.concat([events, more], ignore_index=True) if not events.empty else more
    return both.sort_values("t", kind="stable").reset_index(drop=True)


def replay_units(
    run_dir: Path, network: Network, cfg: PipelineConfig, out: Path, *, force: bool, inputs: Iterable[Path]
) -> tuple[dict[str, Replayed], dict[str, Any]]:
    """Both units on the run (:func:`unit_run`), each one's outputs in ``out/<unit>`` with the
    ``units_disagree`` events (:func:`disagreement_events`), and the comparison
    (:func:`compare_units`, with ``unit_r``: which stream unit R read, :func:`r_sources`) in
    ``out/units.json``, all written atomically."""
    from dataclasses import replace

    results: dict[str, Replayed] = {}
    positions: dict[str, list[pd.DataFrame]] = {u: [] for u in UNITS}
    sinks: dict[str, ResultsWriter] = {}
    with atomic_folder(out, force=force, inputs=inputs) as tmp, tempfile.TemporaryDirectory() as scratch:
        try:
            for unit in UNITS:
                (tmp / unit).mkdir()
                sinks[unit] = sink = ResultsWriter(tmp / unit)

                def consume(part: Any, unit: str = unit, sink: ResultsWriter = sink) -> None:
                    sink.add_positions(part.positions)
                    positions[unit].append(part.positions)

                view = unit_run(read_run(run_dir), unit, Path(scratch) / unit)
                results[unit] = replay_bounded(view, network, cfg, consume)
            frame, summary = compare_units(*(pd.concat(positions[u], ignore_index=True) for u in UNITS))
            for unit in UNITS:
                events = with_events(results[unit].events, disagreement_events(frame, unit))
                results[unit] = replace(results[unit], events=events)
                sinks[unit].finish(events, results[unit].summary)
        finally:
            for sink in sinks.values():
                sink.close()
        sources = r_sources(read_run(run_dir))
        summary["unit_r"] = {"view": r_view(sources), "streams": sources}
        (tmp / "units.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return results, summary
