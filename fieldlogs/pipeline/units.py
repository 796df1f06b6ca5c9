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

Both units position the vehicle's **reference point** (run.json ``vehicle``), so the known
distance between their positions along the track is 0 (each cab end lies its ``x_m`` from it).
:func:`compare_units` puts the two outputs side by side per cycle: where both claim a km, the
difference d = km_F − km_R must lie within the sum of their margins, |d| ≤ m_F + m_R (each
unit's error within its margin implies it), and where both are *determined* their track ids
must agree. A cycle breaking either is a **disagreement**: one of the units is wrong beyond
what it claims, and the summary names the spans.

``trainpos run --unit both`` (:func:`replay_units`) writes each unit's outputs into ``OUT/F``
and ``OUT/R`` and the comparison's summary into ``OUT/units.json``.
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
from dbtools.network import Network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.outputs import ResultsWriter
from fieldlogs.pipeline.windows import Replayed, replay_bounded
from fieldlogs.runs.handle import Run, read_run
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.write import write_run
from schemas.enums import CabDirection, PositionState

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


def mirrored_meta(meta: RunMeta) -> RunMeta:
    from dataclasses import replace

    extra = dict(meta.extra)
    if "radar" in extra:
        extra["radar"] = mirrored_block(extra["radar"])
    vehicle = meta.vehicle
    if vehicle is not None and "balise_reader_r" in vehicle:  # the other cab's reader is unit R's own
        vehicle = {**vehicle, "balise_reader": vehicle["balise_reader_r"], "balise_reader_r": vehicle["balise_reader"]}
    return replace(meta, vehicle=mirrored_block(vehicle), extra=extra)


def unit_run(run: Run, unit: str, folder: Path) -> Run:
    """The run as unit ``unit`` records it: ``run`` itself for F; for R its mirror written to
    ``folder`` (a scratch folder the caller owns)."""
    if unit == "F":
        return run
    if run.meta is None:
        return run  # unusable: the pipeline refuses it with its own message
    streams = {name: frame for name in run.streams_present() if (frame := run.stream(name)) is not None}
    return read_run(write_run(folder, mirrored_meta(run.meta), mirrored_streams(streams), force=True))


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
            "disagree": beyond | other_track,
        }
    )
    t = frame["t"].to_numpy()
    bad = frame["disagree"].to_numpy(dtype=bool)
    edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    spans = [
        [float(t[a]), float(t[b - 1])]
        for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True)
    ]
    summary = {
        "cycles": len(frame),
        "cycles_compared": int(both.sum()),
        "max_abs_difference_m": float(np.nanmax(np.abs(diff))) if both.any() else None,
        "max_difference_share_of_bound": float(np.nanmax(np.abs(diff) / bound)) if both.any() else None,
        "cycles_beyond_margins": int(beyond.sum()),
        "cycles_on_other_tracks": int(other_track.sum()),
        "disagreements": spans,
    }
    return frame, summary


def replay_units(
    run_dir: Path, network: Network, cfg: PipelineConfig, out: Path, *, force: bool, inputs: Iterable[Path]
) -> tuple[dict[str, Replayed], dict[str, Any]]:
    """Both units on the run (:func:`unit_run`), each one's outputs in ``out/<unit>``, and the
    comparison (:func:`compare_units`) in ``out/units.json``, all written atomically."""
    results: dict[str, Replayed] = {}
    positions: dict[str, list[pd.DataFrame]] = {u: [] for u in UNITS}
    with atomic_folder(out, force=force, inputs=inputs) as tmp, tempfile.TemporaryDirectory() as scratch:
        for unit in UNITS:
            (tmp / unit).mkdir()
            sink = ResultsWriter(tmp / unit)
            try:

                def consume(part: Any, unit: str = unit, sink: ResultsWriter = sink) -> None:
                    sink.add_positions(part.positions)
                    positions[unit].append(part.positions)

                view = unit_run(read_run(run_dir), unit, Path(scratch) / unit)
                results[unit] = replay_bounded(view, network, cfg, consume)
                sink.finish(results[unit].events, results[unit].summary)
            finally:
                sink.close()
        _, summary = compare_units(*(pd.concat(positions[u], ignore_index=True) for u in UNITS))
        (tmp / "units.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return results, summary
