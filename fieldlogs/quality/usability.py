"""One rule for whether a run can serve an application (issue 15), shared by ``logs check``,
``run``, ``audit``, ``gis verify``, ``survey``, ``db impact`` and ``possession check``.

What a run needs depends on what it is for and on the vehicle:

* **positioning** (the pipeline: ``run``, ``audit``, ``gis verify``, …) dead-reckons on the
  wheel: a ``tacho`` stream with a plausible wheel (diameter 0.5–1.3 m for a train, 0.2–1.3 m
  for a road-rail vehicle's rail wheels; teeth 1–1000) is needed whatever the vehicle — without
  it the position could not move and would be claimed at a stale km. A train also needs its
  ``imu``: without it slips and slides can neither be detected nor bounded [S000 §3.1], so no
  margin would hold. A road-rail vehicle needs its ``gps`` and ``cab`` (PTO).
* **possession** (``possession check``): ``gps`` and ``cab``; a tacho is used when usable.

Every needed stream must have at least two usable rows (every required column valid), and a
time base in seconds: a stream whose median step is ~10³ (10⁶, 10⁹) times its declared
interval was logged in milliseconds (microseconds, nanoseconds) — said so, not guessed at —
and one more than 30 times off it either way is no stream of that rate (the tacho, whose rows
are the pipeline's 100 ms cycles, within a factor of 2 for positioning). For positioning, the
streams the cycle grid is built from (tacho, IMU) must also cover their time span (part of
``t`` in milliseconds stretches it), and the tacho must be one wheel's count as the pipeline
uses it — sorted by t, resets bridged (:func:`fieldlogs.quality.tacho.counter_problem`): never
negative, not below an earlier count at more than a few rows, no impossible speed; otherwise
the bridging would turn rows shuffled before a reset into kilometres of phantom distance. A
train's IMU must be in m/s² and rad/s (:func:`imu_unit_problems`: gravity's median, the
gyro's 99th percentile), else slips would be detected and corrected on a wrong scale.

A run that fails is refused (FindingsError, exit 1, each problem a finding naming the stream
and column); it is never positioned at a "determined" km it cannot support.
"""

from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum
from pathlib import Path

import numpy as np
import pandas as pd

from fieldlogs.pipeline.block_means import BLOCK_ROWS
from fieldlogs.quality.tacho import counter_problem
from fieldlogs.runs.handle import REQUIRED_STREAMS, Run
from schemas.enums import Severity, VehicleKind
from schemas.errors import FindingsError
from schemas.findings import Finding
from schemas.logs import LOG_STREAMS
from schemas.units import metres_per_pulse
from schemas.vehicle import TEETH_RANGE as TEETH
from schemas.vehicle import WHEEL_DIAMETER_M

#: Time units a stream's ``t`` may have been logged in by mistake: (name, factor to seconds).
WRONG_TIME_UNITS = (("nanoseconds", 1e9), ("microseconds", 1e6), ("milliseconds", 1e3))
#: A median step more than this many times off the declared interval (either way) is no
#: stream of that rate in seconds.
STEP_FACTOR = 30.0
#: The streams the cycle grid is built from (``fieldlogs.pipeline.cycles``): their t must
#: cover their span — span / (rows − 1) at most this many median steps.
SPAN_FACTOR = 10.0
CYCLE_STREAMS = ("tacho", "imu")
#: The tacho's rows are the pipeline's cycles (the onboard unit's 100 ms): for positioning its
#: median step must be within this factor of the declared interval.
TACHO_STEP_FACTOR = 2.0
#: The median |a| of an IMU lies in this band [m/s²]: it always measures gravity.
GRAVITY_BAND_MPS2 = (7.0, 13.0)
#: A train body turns, rolls and pitches far slower: 99 % of max(|ωx|, |ωy|, |ωz|) above this
#: is no rad/s [rad/s] (the sample runs: 0.05; the same in deg/s: 2.8).
MAX_GYRO_P99_RADPS = 1.0


class Purpose(StrEnum):
    POSITIONING = "positioning"
    POSSESSION = "possession"


def needed_streams(kind: str, purpose: Purpose) -> tuple[str, ...]:
    """The streams a run of vehicle ``kind`` needs for ``purpose`` (module docstring)."""
    if purpose == Purpose.POSSESSION:
        return REQUIRED_STREAMS[VehicleKind.ROAD_RAIL.value]
    base = REQUIRED_STREAMS.get(kind, ())
    return base if "tacho" in base else ("tacho", *base)


def usability_findings(run: Run, purpose: Purpose) -> list[Finding]:
    """Why ``run`` cannot serve ``purpose`` (empty: it can)."""
    if run.meta is None:
        errors = [f for f in run.findings if f.severity == Severity.ERROR]
        return errors or [_finding("run.json", "run.json is missing or invalid")]
    out: list[Finding] = []
    for name in needed_streams(run.meta.vehicle_kind, purpose):
        out += _stream_problems(run, name, purpose)
    if purpose == Purpose.POSITIONING:
        out += _wheel_problems(run)
    return out


def require_usable(run: Run, purpose: Purpose) -> None:
    """FindingsError (exit 1) naming every problem when ``run`` cannot serve ``purpose``."""
    problems = usability_findings(run, purpose)
    if problems:
        summary = "; ".join(f"{_where(f)}: {f.message}" for f in problems[:3])
        raise FindingsError(f"unusable run for {purpose} ({summary})", problems, path=run.folder)


def _where(f: Finding) -> str:
    """``tacho.parquet column t``: the file (else the table) and the column of a finding."""
    name = Path(f.file).name if f.file else f.table
    return f"{name} column {f.column}" if f.column else name


def _finding(
    table: str, message: str, column: str | None = None, value: object = None, file: Path | None = None
) -> Finding:
    return Finding(
        "run.unusable", Severity.ERROR, table, message, column=column, value=value, file=str(file) if file else None
    )


def _stream_problems(run: Run, name: str, purpose: Purpose) -> list[Finding]:
    why = {
        "tacho": "the position is dead-reckoned on the wheel",
        "imu": "without it slips and slides can be neither detected nor bounded",
        "gps": "km and track come from the GPS",
        "cab": "on rail = PTO on",
    }.get(name, f"needed for {purpose}")
    if not run.has(name):
        return [_finding(name, f"no {name} stream ({why})")]
    frame = run.stream(name)
    table = LOG_STREAMS[name]
    cols = [c.name for c in table.columns if c.required and not c.nullable]
    usable = _usable_rows(frame, cols) if frame is not None and all(c in frame.columns for c in cols) else 0
    if usable < 2:
        first = next((f for f in run.stream_findings(name) if f.severity == Severity.ERROR), None)
        return [_finding(name, "no usable rows" + (f" ({first.message})" if first else ""))]
    assert frame is not None
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    cycle_grid = name == "tacho" and purpose == Purpose.POSITIONING
    unit = time_unit_problem(t, table.rate_hz, TACHO_STEP_FACTOR if cycle_grid else STEP_FACTOR)
    if unit is None and purpose == Purpose.POSITIONING and name in CYCLE_STREAMS:
        unit = time_span_problem(t, table.rate_hz)
    path = run.stream_file(name)
    if unit:
        return [_finding(name, unit, "t", file=path)]
    if purpose != Purpose.POSITIONING:
        return []
    if name == "tacho":
        counter = counter_problem(t, frame["pulses"].to_numpy(dtype=float, na_value=np.nan), _metres(run))
        return [_finding(name, counter, "pulses", file=path)] if counter else []
    if name == "imu":
        return [_finding(name, msg, col, file=path) for col, msg in imu_unit_problems(frame)]
    return []


def imu_unit_problems(frame: pd.DataFrame, rows: int = BLOCK_ROWS) -> list[tuple[str, str]]:
    """(column, message) when the IMU is not in m/s² and rad/s: the median |a| (gravity is
    always measured, ≈ 9.81 m/s²) outside :data:`GRAVITY_BAND_MPS2` (≈ 1: in g), or the 99th
    percentile of max(|ωx|, |ωy|, |ωz|) above :data:`MAX_GYRO_P99_RADPS` (≈ 57× a train's
    rates: deg/s). |a| and the rate maxima are computed ``rows`` samples at a time into one
    array of the finite values (no n×3 copies of a long run's 100 Hz stream)."""
    out: list[tuple[str, str]] = []
    # |a| as a hypotenuse: a value near the float limit (a broken sample) is inf, not an overflow
    mag = _row_values(frame, ["ax", "ay", "az"], lambda a: np.hypot(np.hypot(a[:, 0], a[:, 1]), a[:, 2]), rows)
    lo, hi = GRAVITY_BAND_MPS2
    if mag.size >= 10 and not lo <= (med := float(np.median(mag, overwrite_input=True))) <= hi:
        hint = "looks like g: multiply by 9.80665" if 0.7 <= med <= 1.3 else "not m/s²"
        out.append(("az", f"median |a| {med:.3g}, gravity is about 9.81 m/s² ({hint})"))
    del mag
    w_max = _row_values(frame, ["wx", "wy", "wz"], lambda w: np.fmax.reduce(np.abs(w), axis=1), rows)
    if w_max.size >= 10 and (p99 := float(np.percentile(w_max, 99, overwrite_input=True))) > MAX_GYRO_P99_RADPS:
        out.append(
            (
                "wz",
                f"99 % of the angular rates below {p99:.3g}, over {MAX_GYRO_P99_RADPS:g} rad/s (deg/s? divide by 57.3)",
            )
        )
    return out


def _row_values(
    frame: pd.DataFrame, cols: list[str], per_row: Callable[[np.ndarray], np.ndarray], rows: int
) -> np.ndarray:
    """The finite values of ``per_row`` (one per row of the n×k array of ``cols``), in row
    order, computed a block of ``rows`` rows at a time (the same row arithmetic as on the
    whole frame: each value depends on its row only)."""
    out = np.empty(len(frame))
    m = 0
    for start in range(0, len(frame), max(rows, 1)):
        v = per_row(frame.iloc[start : start + rows][cols].to_numpy(dtype=float, na_value=np.nan))
        v = v[np.isfinite(v)]
        out[m : m + v.size] = v
        m += v.size
    return out[:m]


def _metres(run: Run) -> float | None:
    """Metres per pulse of a plausible wheel (None: the wheel rule speaks)."""
    meta = run.meta
    if meta is None or _wheel_problems(run) or meta.wheel_diameter_m is None or meta.teeth is None:
        return None
    return metres_per_pulse(meta.wheel_diameter_m, meta.teeth)


def _usable_rows(frame: pd.DataFrame, cols: list[str]) -> int:
    """Rows with every column of ``cols`` valid (column by column: no copy of the frame)."""
    ok = np.ones(len(frame), dtype=bool)
    for c in cols:
        ok &= frame[c].notna().to_numpy()
    return int(np.count_nonzero(ok))


def _steps(t: np.ndarray) -> np.ndarray:
    """Steps between the distinct finite values of ``t``, in time order."""
    finite = np.isfinite(t)
    if not finite.all():
        t = t[finite]
    del finite
    if not bool((t[1:] >= t[:-1]).all()):  # sorted already (the usual case): no sorted copy
        t = np.sort(t)
    step = np.diff(t)
    return step[step > 0]


def time_unit_problem(t: np.ndarray, rate_hz: float | None, factor_off: float = STEP_FACTOR) -> str | None:
    """The message when a stream's median step Δ̃ (distinct t) says its ``t`` is not in
    seconds: Δ̃ within ×0.3–3 of the declared interval 1/rate times 10³, 10⁶ or 10⁹ (named),
    or otherwise more than ``factor_off`` times off it either way."""
    if rate_hz is None:
        return None
    steps = _steps(t)
    if steps.size < 2:
        return None
    step = float(np.median(steps, overwrite_input=True))
    nominal = 1.0 / rate_hz
    for unit, factor in WRONG_TIME_UNITS:
        if 0.3 * factor * nominal <= step <= 3.0 * factor * nominal:
            return (
                f"t looks like {unit}: rows {step:g} apart for a {rate_hz:g} Hz stream "
                f"(t must be seconds since the run's start; divide by {factor:g})"
            )
    if not nominal / factor_off <= step <= factor_off * nominal:
        return (
            f"rows {step:.6g} s apart, not a {rate_hz:g} Hz stream "
            f"({nominal / factor_off:g}–{factor_off * nominal:g} s; t must be seconds since the run's start)"
        )
    return None


def time_span_problem(t: np.ndarray, rate_hz: float | None) -> str | None:
    """The message when ``t`` spans far more than its rows cover: span / (n − 1) above
    :data:`SPAN_FACTOR` times the median step (part of ``t`` in another unit, e.g. rows in
    milliseconds after rows in seconds, or a recorder that stopped for most of the run)."""
    if rate_hz is None:
        return None
    steps = _steps(t)
    if steps.size < 2:
        return None
    span = float(steps.sum())
    step = float(np.median(steps, overwrite_input=True))
    if span <= SPAN_FACTOR * step * steps.size:
        return None
    covered = step * steps.size
    return (
        f"t spans {span:.6g} s but its {steps.size + 1} rows {step:g} s apart cover {covered:.6g} s: "
        "part of t not in seconds (milliseconds?), or the stream stops for most of the run"
    )


def _wheel_problems(run: Run) -> list[Finding]:
    meta = run.meta
    assert meta is not None
    lo, hi = WHEEL_DIAMETER_M.get(meta.vehicle_kind, WHEEL_DIAMETER_M[VehicleKind.TRAIN.value])
    out: list[Finding] = []
    d, teeth = meta.wheel_diameter_m, meta.teeth
    if d is None or teeth is None:
        return out  # no tacho stream: said by the stream rule
    if not (np.isfinite(d) and lo <= d <= hi):
        out.append(
            _finding(
                "run.json",
                f"wheel_diameter_m {d:.6g} m is not a {meta.vehicle_kind}'s wheel ({lo:g}–{hi:g} m)",
                "wheel_diameter_m",
                d,
            )
        )
    if not TEETH[0] <= teeth <= TEETH[1]:
        out.append(_finding("run.json", f"teeth {teeth} is not {TEETH[0]}–{TEETH[1]}", "teeth", teeth))
    return out
