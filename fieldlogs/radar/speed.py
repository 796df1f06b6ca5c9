"""The radar speed meter end to end: raw IF samples → ground speed per frame [S004].

``process_if`` frames the samples (``framing``), computes the spectra and Doppler lines of
blocks of frames at once (``spectrum``), solves eq. 2 for every frame (``solve``) and gives
each frame a status (``schemas.enums.RadarStatus``), first match wins:

1. ``low_quality`` — fewer than ``min_valid`` of the frame's samples present;
2. ``aliased`` — at least ``alias_share`` of the ground-range lines (and ``min_lines``)
   are aliased (and ``min_alias_lines``), or the speed puts the beam's half-power edge θ0 − β_e past the Nyquist
   frequency: V_G·cos(θ0 − β_e) ≥ Vmax (Table 1: 112.14 km/h radial) — no speed;
3. ``standstill`` — no Doppler line but the static ground echo above the threshold, or
   only slow lines without a direction (vibration sidebands on both sides of 0 Hz, below
   ``vibration_max_mps``): speed 0, σ = the lowest measurable speed (the first bin past
   the DC guard at the beam edge), or the fastest such line when faster;
   ``no_reflections`` — no line and no static echo, or lines but none at a ground range —
   no speed;
4. ``low_quality`` — fewer than ``min_lines`` used lines, no clear direction
   (``min_direction``), a failed fit, or σ above both ``max_sigma_mps`` and
   ``max_rel_sigma``·V — no speed;
5. ``ok``.

Speeds are signed along the body x axis (+ toward the F end, like ``truth.speed_mps``):
the sign of the Doppler (+: the ground approaches where the radar looks) times +1 for a
radar looking toward F, −1 toward R.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.atomic import atomic_file
from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.framing import Frames, frame_samples
from fieldlogs.radar.solve import FrameFit, LineClass, fit_frames
from fieldlogs.radar.spectrum import Lines, detect_lines, spectra
from fieldlogs.runs.handle import Run
from schemas.enums import RadarStatus
from schemas.errors import InputError, UsageError
from schemas.findings import Finding
from schemas.outputs import RADAR_SPEED
from schemas.radar import RadarParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
OutFormat = Literal["csv", "json"]


@dataclass
class RadarSpeed:
    """One row per frame (``schemas.outputs.RADAR_SPEED``), plus the radar it came from."""

    params: RadarParams
    columns: dict[str, npt.NDArray[Any]]
    run_id: str = ""
    cfg: RadarConfig = field(default_factory=RadarConfig)
    findings: list[Finding] = field(default_factory=list)
    """Warnings about the input (``convention``: samples in the other I/Q convention)."""

    def __len__(self) -> int:
        return len(self.columns["t"])

    def to_frame(self) -> pd.DataFrame:
        return pd.DataFrame({c: self.columns[c] for c in RADAR_SPEED.column_names})

    def summary(self) -> dict[str, Any]:
        """Frames per status, share of frames with a speed, median σ and lines of ok frames."""
        status = self.columns["status"]
        ok = status == RadarStatus.OK.value
        counts = {s.value: int((status == s.value).sum()) for s in RadarStatus}
        return {
            "frames": len(self),
            "status": counts,
            "with_speed_share": float(np.isfinite(self.columns["speed_mps"]).mean()) if len(self) else 0.0,
            "median_sigma_mps": _median(self.columns["sigma_mps"][ok]),
            "median_lines_used": _median(self.columns["n_used"][ok]),
            "t_epi_s": self.params.t_epi_s,
            "speed_resolution_kmh": self.params.speed_resolution_mps * 3.6,
            "v_max_kmh": self.params.v_max_mps * 3.6,
            "r_max_m": self.params.r_max_m,
        }


def _median(x: npt.NDArray[Any]) -> float | None:
    return float(np.median(x)) if len(x) else None


def lowest_speed_mps(params: RadarParams, cfg: RadarConfig) -> float:
    """Ground speed whose Doppler at the beam edge θ0 − β_e is the first bin past the DC guard."""
    from fieldlogs.radar.spectrum import fft_length

    bin_hz = params.sample_rate_hz / fft_length(params.samples_per_frame)
    edge = math.radians(max(params.depression_deg - params.beam_elev_deg, 0.5))
    return (cfg.dc_guard_bins + 1) * bin_hz * params.wavelength_m / 2.0 / math.cos(edge)


def _status(
    fit: FrameFit, valid: FloatArray, dc_snr: FloatArray, params: RadarParams, cfg: RadarConfig
) -> npt.NDArray[Any]:
    edge = math.cos(math.radians(max(params.depression_deg - params.beam_elev_deg, 0.0)))
    with np.errstate(invalid="ignore"):
        alias_lines = fit.n_alias >= np.maximum(cfg.min_alias_lines, cfg.alias_share * (fit.n_ground + fit.n_alias))
        beyond = fit.v * edge >= params.v_max_mps
        bad_sigma = ~(fit.sigma <= np.maximum(cfg.max_sigma_mps, cfg.max_rel_sigma * fit.v))
    no_lines = fit.n_lines == 0
    static = dc_snr > -math.log(cfg.pfa)
    undirected = ~(fit.consistency >= cfg.min_direction)
    vibration = static & undirected & (fit.n_ground > 0) & (fit.max_vm <= cfg.vibration_max_mps)
    weak = (fit.n_used < cfg.min_lines) | undirected | ~np.isfinite(fit.v) | bad_sigma
    conds = [
        valid < cfg.min_valid,
        alias_lines | beyond,
        (no_lines & static) | vibration,
        no_lines | (fit.n_ground == 0),
        weak,
    ]
    choices = [
        RadarStatus.LOW_QUALITY.value,
        RadarStatus.ALIASED.value,
        RadarStatus.STANDSTILL.value,
        RadarStatus.NO_REFLECTIONS.value,
        RadarStatus.LOW_QUALITY.value,
    ]
    return np.select(conds, choices, default=RadarStatus.OK.value).astype(object)


def _columns(
    fit: FrameFit, frames: Frames, dc_snr: FloatArray, params: RadarParams, cfg: RadarConfig
) -> dict[str, npt.NDArray[Any]]:
    valid = frames.valid_share
    status = _status(fit, valid, dc_snr, params, cfg)
    look = params.look_sign
    ok = status == RadarStatus.OK.value
    still = status == RadarStatus.STANDSTILL.value
    speed = np.where(ok, look * fit.direction * fit.v, np.where(still, 0.0, np.nan))
    rest_sigma = np.maximum(lowest_speed_mps(params, cfg), fit.max_vm)
    sigma = np.where(ok, fit.sigma, np.where(still, rest_sigma, np.nan))
    return {
        "t": frames.t_centre,
        "speed_mps": speed + 0.0,
        "sigma_mps": sigma,
        "status": status,
        "n_lines": fit.n_lines,
        "n_used": np.where(ok, fit.n_used, 0),
        "n_alias": fit.n_alias,
        "residual_m": np.where(ok, fit.residual_m, np.nan),
        "eq1_rms": np.where(ok, fit.eq1_rms, np.nan),
        "snr_db": np.where(ok, fit.snr_db, np.nan),
        "v_eq2_mps": look * fit.direction * fit.v_eq2 + 0.0,
        "v_naive_mps": look * fit.v_naive + 0.0,
        "valid_share": valid,
    }


@dataclass(frozen=True)
class FrameDetail:
    """One frame's lines and fit, for the Doppler–range scatter plot."""

    t: float
    lines: Lines
    classes: LineClass
    fit: FrameFit
    status: str


def analyse_block(frames: Frames, params: RadarParams, cfg: RadarConfig) -> tuple[FrameFit, Lines, FloatArray]:
    """Spectra, lines and fits of a block of frames (the vectorised core)."""
    sp = spectra(frames, cfg)
    lines = detect_lines(sp, params, cfg)
    return fit_frames(lines, frames.n_frames, params, cfg), lines, sp.dc_snr


def process_frames(frames: Frames, params: RadarParams, cfg: RadarConfig = RadarConfig()) -> RadarSpeed:
    """Every frame, in blocks of ``cfg.block_frames`` (the block size changes at most the
    last bit of the float32 FFTs)."""
    parts: list[dict[str, npt.NDArray[Any]]] = []
    step = max(cfg.block_frames, 1)
    for start in range(0, frames.n_frames, step):
        block = frames.block(start, min(start + step, frames.n_frames))
        fit, _lines, dc = analyse_block(block, params, cfg)
        parts.append(_columns(fit, block, dc, params, cfg))
    if not parts:
        empty = {c.name: np.zeros(0, dtype=object if c.dtype == "str" else float) for c in RADAR_SPEED.columns}
        return RadarSpeed(params, empty, cfg=cfg)
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return RadarSpeed(params, cols, cfg=cfg)


def process_if(
    t: npt.ArrayLike,
    i1: npt.ArrayLike,
    q1: npt.ArrayLike,
    i2: npt.ArrayLike,
    q2: npt.ArrayLike,
    params: RadarParams,
    cfg: RadarConfig = RadarConfig(),
) -> RadarSpeed:
    """Ground speed per T_epi frame from the raw samples of both frequencies."""
    return process_frames(frame_samples(t, i1, q1, i2, q2, params), params, cfg)


def frame_detail(frames: Frames, t: float, params: RadarParams, cfg: RadarConfig = RadarConfig()) -> FrameDetail:
    """The frame whose centre is nearest ``t``, analysed alone (same code as the whole run)."""
    if frames.n_frames == 0:
        raise UsageError("the run has no complete radar frame")
    k = int(np.argmin(np.abs(frames.t_centre - t)))
    block = frames.block(k, k + 1)
    fit, lines, dc = analyse_block(block, params, cfg)
    status = str(_columns(fit, block, dc, params, cfg)["status"][0])
    return FrameDetail(float(block.t_centre[0]), lines, fit.classes, fit, status)


def run_frames(run: Run) -> tuple[Frames, RadarParams]:
    """The ``radar_if`` frames of a run and its radar (InputError naming what is missing)."""
    if not run.has("radar_if"):
        raise InputError("the run has no radar_if stream (radar_if.parquet or radar_if.csv)", path=run.folder)
    if run.radar is None:
        bad = [f for f in run.findings if (f.column or "").startswith("radar")]
        why = bad[0].message if bad else "run.json has no 'radar' block (f0_hz, delta_f_hz, t_pri_s, …)"
        raise InputError(f"cannot process radar_if: {why}", path=run.folder / "run.json", column="radar")
    frame = run.stream("radar_if")
    if frame is None:
        msg = next((f.message for f in run.stream_findings("radar_if")), "unreadable")
        raise InputError(f"radar_if: {msg}", path=run.stream_file("radar_if"))
    t = frame["t"].to_numpy(dtype=np.float64, na_value=np.nan)
    i1, q1, i2, q2 = (frame[c].to_numpy(dtype=np.float32, na_value=np.nan) for c in ("i1", "q1", "i2", "q2"))
    return frame_samples(t, i1, q1, i2, q2, run.radar), run.radar


def radar_speed(run_dir: Path | str | Run, cfg: RadarConfig = RadarConfig()) -> RadarSpeed:
    """``trainpos radar speed``: the ground speed of every frame of a run's ``radar_if``."""
    run = run_dir if isinstance(run_dir, Run) else Run(Path(run_dir))
    frames, params = run_frames(run)
    result = process_frames(frames, params, cfg)
    result.run_id = run.run_id
    return result


def speed_json(result: RadarSpeed) -> dict[str, Any]:
    """JSON document: run, radar, summary and one record per frame (NaN → null)."""
    frame = result.to_frame().astype(object)
    records = frame.where(pd.notna(frame), None).to_dict(orient="records")
    return {
        "run_id": result.run_id,
        "radar": result.params.to_json(),
        "summary": result.summary(),
        "findings": [f.to_dict() for f in result.findings],
        "frames": records,
    }


def write_speed(
    result: RadarSpeed, path: Path, fmt: OutFormat, *, force: bool = False, inputs: Sequence[Path] = ()
) -> Path:
    """Write the frames as CSV or JSON atomically (refused if ``path`` exists, unless ``force``)."""
    with atomic_file(Path(path), force=force, inputs=inputs) as tmp:
        if fmt == "csv":
            result.to_frame().to_csv(tmp, index=False, float_format="%.6g", lineterminator="\n")
        else:
            tmp.write_text(json.dumps(speed_json(result), indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    return Path(path)
