"""``logs check`` / ``info`` / ``convert`` / ``repair`` on the gnss_obs and gnss_nav streams."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fieldlogs.quality.checks import check_run
from fieldlogs.quality.info import run_info
from fieldlogs.quality.repair import repair_run
from fieldlogs.runs.handle import Run
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.write import convert_run, write_run
from tests.fieldlogs.make_runs import synthetic_streams
from tests.fieldlogs.recorders.conftest import nav_row, obs_frame


def _run(
    tmp_path: Path, obs: pd.DataFrame, nav: pd.DataFrame, receiver: str = "rx1", *, complete: bool = False
) -> Path:
    """A road-rail run with these GNSS streams; ``complete``: with the gps and cab streams
    a road-rail run needs (else logs check finds them missing)."""
    vehicle = {
        "vehicle_id": "V",
        "vehicle_kind": "road_rail",
        "length_m": 10.0,
        "reference": "centre",
        "front_x_m": 5.0,
        "antennas": [{"id": "a", "receiver": receiver, "x_m": 1.0, "y_m": 0.0, "z_m": 3.0}],
    }
    meta = RunMeta("R", "V", "road_rail", 0.7, 60, "2026-12-01T10:00:00+00:00", vehicle=vehicle)
    obs = obs.copy()
    if "t" not in obs.columns:
        obs.insert(0, "t", obs["gnss_time_s"] - obs["gnss_time_s"].min())
    streams = {"gnss_obs": obs, "gnss_nav": nav}
    if complete:
        rest = synthetic_streams(3, vehicle_kind="road_rail")
        streams |= {k: rest[k] for k in ("gps", "cab")}
    return write_run(tmp_path / "r", meta, streams)


def _rules(path: Path) -> dict[str, int]:
    out: dict[str, int] = {}
    for f in check_run(path):
        out[f.rule] = out.get(f.rule, 0) + 1
    return out


def test_clean_run(tmp_path: Path) -> None:
    p = _run(tmp_path, obs_frame(3), pd.DataFrame([nav_row("G07"), nav_row("E11")]))
    assert _rules(p) == {"log.missing_stream": 2}  # a road-rail run needs gps and cab
    info = run_info(p)
    names = {s.name: s for s in info.streams}
    assert names["gnss_obs"].rows == 21 and names["gnss_obs"].t_end_s == 2.0
    assert names["gnss_nav"].rows == 2 and names["gnss_nav"].t_start_s is None


def test_damaged_streams_are_reported(tmp_path: Path) -> None:
    obs = obs_frame(3)
    obs.insert(0, "t", obs["gnss_time_s"] - obs["gnss_time_s"].min())
    obs = pd.concat([obs, obs.iloc[[0]]], ignore_index=True)  # a repeated key
    obs.loc[5, "sat"] = "G7"
    obs.loc[6, "signal"] = "L1C"
    obs.loc[7, "gnss_time_s"] += 0.5  # not on the run's time base
    nav = pd.DataFrame(
        [nav_row("G07"), nav_row("G07"), {**nav_row("J02"), "sqrtA": np.nan}, {**nav_row("E11"), "Eccentricity": 0.7}]
    )
    p = _run(tmp_path, obs, nav, receiver="other")
    rules = _rules(p)
    assert rules["log.duplicate_key"] == 1
    assert rules["log.gnss_id"] == 2
    assert rules["log.time_base"] == 1
    assert rules["log.nav_field"] == 1
    assert rules["log.nav_range"] == 1
    assert rules["log.duplicate_row"] == 1
    assert rules["vehicle.receiver"] == 1


def test_repair_sorts_and_drops_and_convert_round_trips(tmp_path: Path) -> None:
    obs = obs_frame(3)
    shuffled = pd.concat([obs.iloc[::-1], obs.iloc[[2]]], ignore_index=True)
    nav = pd.DataFrame([nav_row("J02"), nav_row("G07"), nav_row("G07")])
    p = _run(tmp_path, shuffled, nav, complete=True)  # repair refuses a run with problems it cannot fix
    assert _rules(p).get("log.unsorted", 0) > 0
    res = repair_run(p, tmp_path / "fixed")
    actions = {(s.stream, a.action): a.count for s in res.streams for a in s.actions}
    assert actions[("gnss_obs", "drop_duplicate_rows")] == 1
    assert actions[("gnss_nav", "drop_duplicate_rows")] == 1
    assert ("gnss_obs", "sort_by_key") in actions
    fixed = Run(tmp_path / "fixed")
    o = fixed.stream("gnss_obs")
    assert o is not None and len(o) == len(obs) and (np.diff(o["t"]) >= 0).all()
    assert "log.unsorted" not in _rules(tmp_path / "fixed")
    convert_run(tmp_path / "fixed", tmp_path / "csv", "csv")
    convert_run(tmp_path / "csv", tmp_path / "pq", "parquet")
    for name in ("gnss_obs", "gnss_nav"):
        a, b = fixed.stream(name), Run(tmp_path / "pq").stream(name)
        assert a is not None and b is not None
        pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9)
    assert Run(tmp_path / "pq").raw_json["vehicle"]["antennas"][0]["receiver"] == "rx1"


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_gnss_streams_read_in_both_formats(tmp_path: Path, fmt: str) -> None:
    obs = obs_frame(2)
    obs.insert(0, "t", obs["gnss_time_s"] - obs["gnss_time_s"].min())
    meta = RunMeta("R", "V", "train", 0.86, 90, "2026-12-01T10:00:00+00:00")
    write_run(tmp_path / "r", meta, {"gnss_obs": obs}, fmt=fmt)  # type: ignore[arg-type]
    got = Run(tmp_path / "r").stream("gnss_obs")
    assert got is not None
    assert got["lli"].tolist() == obs["lli"].tolist()
    np.testing.assert_allclose(got["pseudorange_m"], obs["pseudorange_m"], rtol=1e-9)


def _with_sbas(tmp_path: Path, rows: list[dict[str, object]]) -> Path:
    from fieldlogs.runs.handle import read_run

    run = read_run(_run(tmp_path, obs_frame(3), pd.DataFrame([nav_row("G07"), nav_row("E11")])))
    streams = {n: run.stream(n) for n in ("gnss_obs", "gnss_nav")}
    streams["gnss_sbas"] = pd.DataFrame(rows)
    assert run.meta is not None
    return write_run(tmp_path / "with-sbas", run.meta, streams)


def _sbas_row(t: float, prn: int, seq: int) -> dict[str, object]:
    from fieldlogs.simulate.gnss.sbas_encode import mt1

    return {"t": t, "gnss_time_s": 1e9 + t, "prn": prn, "msg_type": 1, "message_hex": mt1([7, 11], 0, seq).hex()}


def test_two_geos_logging_in_the_same_second_are_a_clean_sbas_stream(tmp_path: Path) -> None:
    """MSAS PRN 129 and 137 both received every second: one row per (prn, t), no finding."""
    p = _with_sbas(tmp_path, [_sbas_row(float(k), prn, k) for k in range(3) for prn in (129, 137)])
    assert _rules(p) == {"log.missing_stream": 2}


def test_a_damaged_sbas_stream_is_reported(tmp_path: Path) -> None:
    rows = [_sbas_row(float(k), prn, k) for k in range(3) for prn in (129, 137)]
    rows.append(rows[0])  # an exact repeat: a warning
    rows.append({**_sbas_row(0.0, 137, 2)})  # another message under an existing key: an error
    rows.insert(3, _sbas_row(0.5, 129, 1))  # PRN 129 goes back from t 1 to 0.5
    rules = _rules(_with_sbas(tmp_path, rows))
    assert rules["log.duplicate_row"] == 1
    assert rules["log.duplicate_key"] == 1
    assert rules["log.unsorted"] == 3  # the 0.5 s row, and the two appended rows back at t 0
    assert "log.duplicate_t" not in rules
