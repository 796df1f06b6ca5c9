"""The radar_if stream and the run.json 'radar' block: parsing, range checks, float32
Parquet, and what ``logs check`` / ``logs info`` say about them."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from fieldlogs.quality.checks import check_run
from fieldlogs.quality.info import run_info
from fieldlogs.runs.handle import Run
from fieldlogs.runs.write import write_run
from schemas.enums import Severity
from schemas.radar import RadarParams, parse_radar_block
from tests.fieldlogs.make_runs import make_meta, synthetic_streams

BLOCK: dict[str, Any] = {
    "f0_hz": 24.06e9,
    "delta_f_hz": 12.75e6,
    "t_pri_s": 50e-6,
    "t_epi_s": 0.307,
    "height_m": 0.8,
    "depression_deg": 45.0,
    "beam_elev_deg": 7.5,
    "beam_az_deg": 3.0,
}


def parse(block: Any) -> tuple[RadarParams | None, list[Any]]:
    return parse_radar_block({"radar": block}, Path("run.json"))


def test_valid_block_gives_the_params() -> None:
    p, findings = parse(BLOCK)
    assert findings == [] and p == RadarParams(**BLOCK)
    assert p.looks_toward == "F" and p.look_sign == 1
    p2, _ = parse({**BLOCK, "looks_toward": "R"})
    assert p2 is not None and p2.look_sign == -1
    assert parse_radar_block({}, Path("run.json")) == (None, [])


@pytest.mark.parametrize(
    ("change", "column", "text"),
    [
        ({"f0_hz": None}, "radar.f0_hz", "missing"),
        ({"t_pri_s": "50us"}, "radar.t_pri_s", "not a number"),
        ({"height_m": 12.0}, "radar.height_m", "outside 0.05–5"),
        ({"beam_az_deg": True}, "radar.beam_az_deg", "not a number"),
        ({"looks_toward": "up"}, "radar.looks_toward", "not F or R"),
        ({"depression_deg": 80.0, "beam_elev_deg": 15.0}, "radar.depression_deg", "between 0° and 90°"),
        ({"depression_deg": 8.0, "beam_elev_deg": 5.0}, "radar.delta_f_hz", "beyond the unambiguous range"),
        ({"t_epi_s": 1e-3}, "radar.t_epi_s", "at least 16"),
    ],
)
def test_bad_blocks_are_findings_naming_the_field(change: dict[str, Any], column: str, text: str) -> None:
    block = {k: v for k, v in {**BLOCK, **change}.items() if v is not None}
    p, findings = parse(block)
    assert p is None
    err = [f for f in findings if f.severity == Severity.ERROR]
    assert len(err) == 1 and err[0].column == column and text in err[0].message, findings


def test_not_an_object_and_unknown_keys() -> None:
    p, findings = parse([1, 2])
    assert p is None and findings[0].column == "radar"
    p, findings = parse({**BLOCK, "hieght_m": 1.0})
    assert p is not None and findings[0].severity == Severity.WARNING and "height_m" in findings[0].message


def if_rows(seconds: float, step_s: float = 1e-4) -> pd.DataFrame:
    rng = np.random.default_rng(0)
    n = round(seconds / step_s)
    x = (0.05 * rng.standard_normal((n, 4))).astype(np.float32)
    return pd.DataFrame({"t": np.arange(n) * step_s, "i1": x[:, 0], "q1": x[:, 1], "i2": x[:, 2], "q2": x[:, 3]})


def write(tmp: Path, radar_if: pd.DataFrame, block: dict[str, Any] | None = BLOCK, fmt: str = "parquet") -> Path:
    meta = make_meta()
    if block is not None:
        meta.extra["radar"] = block
    streams = synthetic_streams(3.0)
    streams["radar_if"] = radar_if
    return write_run(tmp / "run", meta, streams, fmt=fmt)  # type: ignore[arg-type]


def test_parquet_keeps_samples_as_float32_and_t_as_float64(tmp_path: Path) -> None:
    d = if_rows(1.0)
    folder = write(tmp_path, d)
    schema = pq.read_schema(folder / "radar_if.parquet")
    assert str(schema.field("t").type) == "double" and str(schema.field("i1").type) == "float"
    assert schema.field("q2").metadata == {b"unit": b"FS"}
    run = Run(folder)
    frame = run.stream("radar_if")
    assert frame is not None and frame["i1"].dtype == np.float32 and frame["t"].dtype == np.float64
    assert np.array_equal(frame["q2"].to_numpy(), d["q2"].to_numpy())
    assert run.radar == RadarParams(**BLOCK) and run.stream_rate_hz("radar_if") == pytest.approx(10_000.0)
    assert json.loads((folder / "run.json").read_text())["radar"] == BLOCK


def test_check_is_clean_on_a_good_radar_run(tmp_path: Path) -> None:
    findings = check_run(write(tmp_path, if_rows(2.0)))
    assert [f for f in findings if f.table in ("radar_if", "run.json")] == []


def test_check_rate_against_t_pri_gaps_and_range(tmp_path: Path) -> None:
    slow = if_rows(2.0, step_s=2e-4)  # 5 kHz while run.json says 1/(2·50 µs) = 10 kHz
    findings = check_run(write(tmp_path / "a", slow))
    rate = [f for f in findings if f.rule == "log.rate" and f.table == "radar_if"]
    assert len(rate) == 1 and rate[0].limit == pytest.approx(10_000.0)
    ok_rate = check_run(write(tmp_path / "b", slow, {**BLOCK, "t_pri_s": 100e-6}))
    assert not [f for f in ok_rate if f.rule == "log.rate"]
    gap = if_rows(2.0)
    gap = gap[(gap["t"] < 0.5) | (gap["t"] > 0.51)].reset_index(drop=True)
    gap.loc[7, "i2"] = 1.5  # beyond the ADC full scale
    found = check_run(write(tmp_path / "c", gap, fmt="csv"))
    gaps = [f for f in found if f.rule == "log.gap" and f.table == "radar_if"]
    assert len(gaps) == 1 and gaps[0].row == 5002
    assert any(f.table == "radar_if" and f.column == "i2" and f.row == 9 for f in found)


def test_radar_if_without_radar_block(tmp_path: Path) -> None:
    folder = write(tmp_path, if_rows(1.0), block=None)
    findings = check_run(folder)
    miss = [f for f in findings if f.rule == "log.radar_params"]
    assert len(miss) == 1 and miss[0].severity == Severity.ERROR and "radar" in miss[0].message
    info = {s.name: s for s in run_info(folder).streams}
    assert info["radar_if"].declared_rate_hz == pytest.approx(10_000.0)  # Table 1 nominal


def test_bad_radar_block_is_a_check_finding(tmp_path: Path) -> None:
    folder = write(tmp_path, if_rows(1.0), block={**BLOCK, "height_m": -1.0})
    findings = check_run(folder)
    assert any(f.rule == "log.run_json_radar" and f.column == "radar.height_m" for f in findings)
    assert not any(f.rule == "log.radar_params" for f in findings)
