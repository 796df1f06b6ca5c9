"""CSV/Parquet mappings: units, time bases, axes, offsets, and the refusals."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from fieldlogs.recorders.tabular import load_mapping, read_mapped
from schemas.errors import FindingsError, InputError

G = 9.80665


def _imu_file(tmp_path: Path, n: int = 20, **cols: Any) -> Path:
    base = {"time": np.arange(n) * 10.0, "ax": 0.0, "ay": 0.0, "az": 1.0, "wx": 0.0, "wy": 0.0, "wz": 0.0}
    base.update(cols)
    p = tmp_path / "imu.csv"
    pd.DataFrame(base).to_csv(p, index=False)
    return p


def _mapping(**over: Any) -> dict[str, Any]:
    m: dict[str, Any] = {
        "stream": "imu",
        "time": {"column": "time", "unit": "ms", "base": "gps"},
        "units": {"ax": "g", "ay": "g", "az": "g", "wx": "deg/s", "wy": "deg/s", "wz": "deg/s"},
    }
    m.update(over)
    return m


def test_units_and_time_by_hand(tmp_path: Path) -> None:
    p = _imu_file(tmp_path, ax=0.5, wz=-90.0)
    f = read_mapped(p, _mapping()).frames["imu"]
    assert f["gnss_time_s"].iloc[1] == pytest.approx(0.010)
    assert f["ax"].iloc[0] == pytest.approx(0.5 * G) and f["az"].iloc[0] == pytest.approx(G)
    assert f["wz"].iloc[0] == pytest.approx(-np.pi / 2)


def test_axes_remap_and_offsets(tmp_path: Path) -> None:
    # sensor mounted turned 90° left about z: sensor x points to the body's left (+y), sensor y backwards
    p = _imu_file(tmp_path, ax=0.1, ay=-0.2, wx=1.0, wy=2.0)
    m = _mapping(axes={"x": "-y", "y": "+x", "z": "+z"}, offsets={"az": -0.05})
    f = read_mapped(p, m).frames["imu"]
    assert f["ax"].iloc[0] == pytest.approx(0.2 * G)  # body x = −sensor y
    assert f["ay"].iloc[0] == pytest.approx(0.1 * G)  # body y = +sensor x
    assert f["az"].iloc[0] == pytest.approx(G - 0.05)
    assert f["wx"].iloc[0] == pytest.approx(-np.radians(2.0)) and f["wy"].iloc[0] == pytest.approx(np.radians(1.0))


def test_a_mirror_image_is_refused(tmp_path: Path) -> None:
    p = _imu_file(tmp_path)
    with pytest.raises(InputError, match="not a rotation"):
        read_mapped(p, _mapping(axes={"x": "+x", "y": "-y", "z": "+z"}))


@pytest.mark.parametrize(
    ("base", "values", "expected"),
    [
        ("unix", [1_483_228_800.0, 1_483_228_801.0], 13_510 * 86_400.0 + 18.0),
        ("utc", ["2017-01-01T09:00:00+09:00", "2017-01-01T09:00:01+09:00"], 13_510 * 86_400.0 + 18.0),
        ("gps", [1e9, 1e9 + 1], 1e9),
    ],
)
def test_time_bases(tmp_path: Path, base: str, values: list[Any], expected: float) -> None:
    p = tmp_path / "t.csv"
    pd.DataFrame({"when": values, "speed": [36.0, 36.0]}).to_csv(p, index=False)
    m = {
        "stream": "radar",
        "time": {"column": "when", "base": base},
        "columns": {"speed_mps": "speed"},
        "units": {"speed_mps": "km/h"},
    }
    f = read_mapped(p, m).frames["radar"]
    assert f["gnss_time_s"].iloc[0] == expected
    assert f["speed_mps"].iloc[0] == pytest.approx(10.0)


def test_relative_time_without_start_is_aligned_later(tmp_path: Path) -> None:
    p = _imu_file(tmp_path)
    dec = read_mapped(p, _mapping(time={"column": "time", "unit": "ms"}))
    assert "recorder_s" in dec.frames["imu"].columns
    assert dec.notes == ["relative time without [time] start: aligned to the run's start"]


def test_units_that_cannot_be_right(tmp_path: Path) -> None:
    p = _imu_file(tmp_path)
    with pytest.raises(FindingsError, match="look like g") as exc:
        read_mapped(p, _mapping(units={"wx": "deg/s"}))
    assert exc.value.findings[0].file == str(p)
    fast = _imu_file(tmp_path, az=1.0, wz=np.linspace(-60, 60, 20))  # deg/s declared as rad/s
    with pytest.raises(FindingsError, match="deg/s declared as rad/s"):
        read_mapped(fast, _mapping(units={"ax": "g", "ay": "g", "az": "g"}))


@pytest.mark.parametrize(
    ("mapping", "message", "column"),
    [
        (_mapping(columns={"ax": "acc_x"}), "names column 'acc_x'", "acc_x"),
        (_mapping(columns={"accx": "ax"}), "target 'accx' is not a column of imu", "columns.accx"),
        (_mapping(units={"ax": "furlong"}), "unit 'furlong'", "units.ax"),
        (_mapping(time={"column": "time", "unit": "min"}), "time unit 'min'", "time.unit"),
        (_mapping(time={"column": "time", "base": "tai"}), "time base 'tai'", "time.base"),
    ],
)
def test_mapping_errors_name_file_and_column(
    tmp_path: Path, mapping: dict[str, Any], message: str, column: str
) -> None:
    p = _imu_file(tmp_path)
    with pytest.raises(InputError, match=message) as exc:
        read_mapped(p, mapping)
    assert exc.value.column == column


def test_load_mapping_refusals(tmp_path: Path) -> None:
    p = tmp_path / "m.toml"
    p.write_text('stream = "imu"\n[tim]\ncolumn = "t"\n')
    with pytest.raises(InputError, match="did you mean 'time'"):
        load_mapping(p)
    p.write_text('stream = "gnss_obs"\n[time]\ncolumn = "t"\n')
    with pytest.raises(InputError, match="not a stream a mapping can fill"):
        load_mapping(p)
    p.write_text("stream = \n")
    with pytest.raises(InputError, match="not valid TOML"):
        load_mapping(p)


def test_parquet_source(tmp_path: Path) -> None:
    csv = _imu_file(tmp_path)
    pq = tmp_path / "imu.parquet"
    pd.read_csv(csv).to_parquet(pq)
    a = read_mapped(csv, _mapping()).frames["imu"]
    b = read_mapped(pq, _mapping()).frames["imu"]
    pd.testing.assert_frame_equal(a, b)


def test_a_cell_that_is_not_a_number_is_named_by_line(tmp_path: Path) -> None:
    p = _imu_file(tmp_path)
    lines = p.read_text().splitlines()
    lines[5] = lines[5].replace("1.0", "one", 1)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="'one' is not a number") as exc:
        read_mapped(p, _mapping())
    assert (exc.value.row, exc.value.column) == (6, "az")
