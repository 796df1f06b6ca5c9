"""Clean synthetic runs for tests and benchmarks (seeded, vectorised, no DB needed).

Tacho 10 Hz cumulative pulses, IMU 100 Hz, GPS 1 Hz, balise and cab events. The vehicle
accelerates at 0.5 m/s² up to 15 m/s and runs east from the tiny source set's first GIS
point (line 0420, track D, 35.9° N 139.4° E), passing the I1/I2 pair of station 01.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.typed import LogFormat
from fieldlogs.runs.write import write_run
from schemas.units import metres_per_pulse

G = 9.80665
WHEEL_D_M = 0.86
TEETH = 90
LAT0, LON0 = 35.9, 139.40
M_PER_DEG_LAT = 111_320.0


def make_meta(run_id: str = "R001", vehicle_kind: str = "train") -> RunMeta:
    return RunMeta(
        run_id=run_id,
        vehicle_id="V01" if vehicle_kind == "train" else "RR01",
        vehicle_kind=vehicle_kind,
        wheel_diameter_m=WHEEL_D_M,
        teeth=TEETH,
        start_time="2026-01-15T09:00:00+09:00",
        db_version="test",
        notes="synthetic",
    )


def _profile(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(distance m, speed m/s, acceleration m/s²) at times t: 0.5 m/s² up to 15 m/s."""
    a0, vmax = 0.5, 15.0
    t1 = vmax / a0
    acc = np.where(t < t1, a0, 0.0)
    v = np.minimum(a0 * t, vmax)
    d = np.where(t < t1, 0.5 * a0 * t**2, 0.5 * a0 * t1**2 + vmax * (t - t1))
    return d, v, acc


def synthetic_streams(
    seconds: float = 10.0, *, seed: int = 0, vehicle_kind: str = "train", t_offset: float = 0.0
) -> dict[str, pd.DataFrame]:
    """The stream frames of a clean run of ``seconds`` seconds (``t_offset`` shifts every t)."""
    rng = np.random.default_rng(seed)
    n_tacho = round(seconds * 10)
    n_imu = round(seconds * 100)
    n_gps = max(round(seconds), 1)
    k = metres_per_pulse(WHEEL_D_M, TEETH)

    t_tacho = np.arange(n_tacho) / 10.0
    d, _, _ = _profile(t_tacho)
    tacho = pd.DataFrame({"t": t_tacho + t_offset, "pulses": np.floor(d / k).astype(np.int64)})

    t_imu = np.arange(n_imu) / 100.0
    _, _, acc = _profile(t_imu)
    noise = rng.normal(0.0, 0.02, size=(n_imu, 6))
    imu = pd.DataFrame(
        {
            "t": t_imu + t_offset,
            "ax": acc + noise[:, 0],
            "ay": noise[:, 1],
            "az": G + noise[:, 2],
            "wx": noise[:, 3] * 0.05,
            "wy": noise[:, 4] * 0.05,
            "wz": noise[:, 5] * 0.05,
        }
    )

    t_gps = np.arange(n_gps, dtype=float)
    d_gps, _, _ = _profile(t_gps)
    fix = np.full(n_gps, 2, dtype=np.int64)
    fix[::7] = 1
    gps = pd.DataFrame(
        {
            "t": t_gps + t_offset,
            "lat": LAT0 + rng.normal(0, 1e-6, n_gps),
            "lon": LON0 + d_gps / (M_PER_DEG_LAT * np.cos(np.radians(LAT0))),
            "fix": fix,
            "nsat": np.full(n_gps, 9, dtype=np.int64),
            "hdop": np.full(n_gps, 0.9),
        }
    )

    t_ev = min(1.0, seconds / 4)
    balise = pd.DataFrame(
        {
            "t": [t_ev + t_offset, t_ev + 0.5 + t_offset],
            "kind": ["I1", "I2"],
            "line_code": ["0420", None],
            "station_code": [None, "01"],
            "track": [None, "D"],
            "signal_type": [None, None],
        }
    ).astype({"kind": "string", "line_code": "string", "station_code": "string", "track": "string"})
    balise["signal_type"] = balise["signal_type"].astype("string")

    cab = pd.DataFrame(
        {
            "t": [0.0 + t_offset],
            "direction": pd.array(["F"], dtype="string"),
            "pto": pd.array([1 if vehicle_kind == "road_rail" else None], dtype="Int64"),
        }
    )
    streams = {"tacho": tacho, "imu": imu, "balise": balise, "gps": gps, "cab": cab}
    if vehicle_kind == "road_rail":
        del streams["balise"]
    return streams


def make_run(
    folder: Path,
    seconds: float = 10.0,
    *,
    fmt: LogFormat = "csv",
    seed: int = 0,
    run_id: str = "R001",
    vehicle_kind: str = "train",
    t_offset: float = 0.0,
) -> Path:
    """Write a clean synthetic run folder and return it."""
    streams = synthetic_streams(seconds, seed=seed, vehicle_kind=vehicle_kind, t_offset=t_offset)
    return write_run(Path(folder), make_meta(run_id, vehicle_kind), streams, fmt=fmt)
