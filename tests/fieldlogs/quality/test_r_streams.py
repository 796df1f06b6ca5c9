"""``logs check`` checks the R cab's own streams (``imu_r``, ``tacho_r``, ``gps_r``: a unit per
cab [S003 §2]) as the sensors they are: the same rules, naming the R stream."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from fieldlogs.quality.checks import check_run
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.write import write_run
from schemas.units import G


def _imu(az: float) -> pd.DataFrame:
    n = 100
    z = np.zeros(n)
    return pd.DataFrame({"t": np.round(np.arange(n) * 0.01, 2), "ax": z, "ay": z, "az": az, "wx": z, "wy": z, "wz": z})


def test_the_r_cabs_streams_get_their_sensors_rules(tmp_path: Path) -> None:
    """An R cab IMU logging in g (az ≈ 1) and an R cab tacho counting down at one row are the
    R streams' findings; the F streams, right, have none."""
    tacho = pd.DataFrame({"t": np.round(np.arange(10) * 0.1, 1), "pulses": np.arange(10) * 5})
    bad = tacho.assign(pulses=[0, 5, 10, 15, 12, 25, 30, 35, 40, 45])
    streams = {"imu": _imu(G), "tacho": tacho, "imu_r": _imu(1.0), "tacho_r": bad}
    meta = RunMeta("R1", "V", "train", 0.86, 90, "2026-01-15T10:00:00+09:00")
    findings = check_run(write_run(tmp_path / "run", meta, streams))
    errors = {(f.rule, f.table) for f in findings if f.severity == "error"}
    assert ("log.unit_suspect", "imu_r") in errors
    assert ("log.pulse_decrease", "tacho_r") in errors
    assert not {t for _, t in errors} & {"imu", "tacho"}
