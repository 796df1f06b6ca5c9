"""The declared I/Q convention and ADC full scale of ``radar_if`` (issue 32 item 12).

Samples are built here by hand (``signals``: point reflectors on flat ground,
A·exp(j(2π·f_d·t − 4π·f_k·R/c)), not the simulator). A recorder wired ``i-jq`` writes
Q' = −Q: the conjugate, whose Doppler (−f_d) and f1–f2 phase (−Δφ, range Rmax − R) are
both mirrored, so as ``i+jq`` no frame has a line at a ground range. Declared, the chain
negates Q back — exactly, so the speeds are bit-for-bit those of the original samples.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from fieldlogs.quality.checks import check_run
from fieldlogs.radar.command import radar_speed_command
from fieldlogs.radar.convention import check_convention, convention_finding
from fieldlogs.radar.framing import frame_samples
from fieldlogs.radar.speed import RadarSpeed, process_if
from fieldlogs.runs.write import write_run
from schemas.enums import RadarStatus, Severity
from schemas.radar import RadarParams, parse_radar_block
from tests.fieldlogs.make_runs import make_meta, synthetic_streams
from tests.fieldlogs.radar.signals import TABLE1, ground_if, reflector_if

DEGREES = list(np.arange(38.0, 52.5, 1.5))
V_G = 20.0


def run(d: dict[str, np.ndarray], p: RadarParams = TABLE1) -> RadarSpeed:
    return process_if(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], p)


def conjugated(d: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {**d, "q1": -d["q1"], "q2": -d["q2"]}


@pytest.fixture(scope="module")
def ground() -> dict[str, np.ndarray]:
    return ground_if(TABLE1, V_G, DEGREES, frames=4, noise=3e-3)


def test_a_conjugated_tone_is_the_mirrored_line() -> None:
    """One reflector at f_d = +1000 Hz, R = 1.1 m: conjugated, its line is at −1000 Hz and its
    range at Rmax − 1.1 m (Rmax = c/(2·Δf) = 11.756 m) — by hand."""
    from fieldlogs.radar.config import RadarConfig
    from fieldlogs.radar.spectrum import detect_lines, spectra

    d = conjugated(reflector_if(TABLE1, 1000.0, 1.1, frames=1))
    lines = detect_lines(
        spectra(frame_samples(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], TABLE1), RadarConfig()), TABLE1, RadarConfig()
    )
    k = int(np.argmax(lines.snr))
    assert lines.fd_hz[k] == pytest.approx(-1000.0, abs=0.5)
    assert lines.range_m[k] == pytest.approx(TABLE1.r_max_m - 1.1, abs=0.01)
    declared = replace(TABLE1, iq_convention="i-jq")
    back = detect_lines(
        spectra(frame_samples(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], declared), RadarConfig()),
        declared,
        RadarConfig(),
    )
    k = int(np.argmax(back.snr))
    assert (back.fd_hz[k], back.range_m[k]) == (pytest.approx(1000.0, abs=0.5), pytest.approx(1.1, abs=0.01))


def test_conjugated_samples_give_the_same_speed_once_declared(ground: dict[str, np.ndarray]) -> None:
    want = run(ground).columns
    assert list(want["status"]) == ["ok"] * 4 and np.all(np.abs(want["speed_mps"] - V_G) < 0.03)
    conj = conjugated(ground)
    silent = run(conj).columns  # before: every moving frame no_reflections, exit 0, no word
    assert set(silent["status"]) == {RadarStatus.NO_REFLECTIONS.value}
    got = run(conj, replace(TABLE1, iq_convention="i-jq")).columns
    assert list(got["status"]) == ["ok"] * 4
    np.testing.assert_array_equal(got["speed_mps"], want["speed_mps"])  # negation is exact


def test_the_other_convention_is_detected_and_named(ground: dict[str, np.ndarray]) -> None:
    conj = conjugated(ground)
    frames = frame_samples(conj["t"], conj["i1"], conj["q1"], conj["i2"], conj["q2"], TABLE1)
    check = check_convention(frames, TABLE1)
    assert (check.sampled, check.ok_declared, check.ok_conjugated, check.mismatch) == (4, 0, 4, True)
    f = convention_finding(check, "radar_if.parquet")
    assert f is not None and f.severity == Severity.WARNING and f.table == "radar_if"
    assert '"iq_convention": "i-jq"' in f.message and f.column == "radar.iq_convention"
    # correct samples, or conjugated ones declared: no finding
    right = frame_samples(ground["t"], ground["i1"], ground["q1"], ground["i2"], ground["q2"], TABLE1)
    assert check_convention(right, TABLE1).ok_conjugated == 0 and not check_convention(right, TABLE1).mismatch
    declared = replace(TABLE1, iq_convention="i-jq")
    again = frame_samples(conj["t"], conj["i1"], conj["q1"], conj["i2"], conj["q2"], declared)
    assert convention_finding(check_convention(again, declared), "x") is None


def test_adc_counts_with_the_declared_full_scale_give_the_same_speed(ground: dict[str, np.ndarray]) -> None:
    want = run(ground).columns
    # a power of two scales exactly: bit-for-bit the same speeds
    exact = {k: (v if k == "t" else (v * 2048.0).astype(np.float32)) for k, v in ground.items()}
    same = run(exact, replace(TABLE1, full_scale=2048.0)).columns
    np.testing.assert_array_equal(same["speed_mps"], want["speed_mps"])
    # 12-bit counts, rounded as an ADC would: the same speed within its 1σ
    counts = {k: (v if k == "t" else np.round(v * 2047.0).astype(np.float32)) for k, v in ground.items()}
    got = run(counts, replace(TABLE1, full_scale=2047.0)).columns
    assert list(got["status"]) == ["ok"] * 4
    assert np.all(np.abs(got["speed_mps"] - want["speed_mps"]) < got["sigma_mps"])


BLOCK: dict[str, Any] = TABLE1.to_json()


def test_the_block_declares_them_once() -> None:
    p, found = parse_radar_block({"radar": {**BLOCK, "iq_convention": "i-jq", "full_scale": 2047}}, Path("run.json"))
    assert found == [] and p is not None and (p.iq_convention, p.full_scale, p.q_sign) == ("i-jq", 2047.0, -1.0)
    base = {k: v for k, v in BLOCK.items() if k not in ("iq_convention", "full_scale")}
    p, found = parse_radar_block({"radar": base}, Path("run.json"))
    assert found == [] and p is not None and (p.iq_convention, p.full_scale) == ("i+jq", 1.0)
    for bad, column in (({"iq_convention": "q+ji"}, "radar.iq_convention"), ({"full_scale": 0}, "radar.full_scale")):
        p, found = parse_radar_block({"radar": {**base, **bad}}, Path("run.json"))
        assert p is None and [f.column for f in found] == [column]


def _write(tmp: Path, d: dict[str, np.ndarray], block: dict[str, Any]) -> Path:
    meta = make_meta()
    meta.extra["radar"] = block
    streams = synthetic_streams(3.0)
    streams["radar_if"] = pd.DataFrame(d)
    return write_run(tmp / "run", meta, streams, fmt="parquet")  # type: ignore[arg-type]


def test_logs_check_and_radar_speed_flag_the_other_convention(ground: dict[str, np.ndarray], tmp_path: Path) -> None:
    folder = _write(tmp_path / "a", conjugated(ground), BLOCK)
    found = [f for f in check_run(folder) if f.table == "radar_if"]
    assert [f.rule for f in found] == ["radar.iq_convention"] and "i-jq" in found[0].message
    result = radar_speed_command(folder)
    assert [f.rule for f in result.findings] == ["radar.iq_convention"]
    declared = _write(tmp_path / "b", conjugated(ground), {**BLOCK, "iq_convention": "i-jq"})
    assert [f for f in check_run(declared) if f.table == "radar_if"] == []
    good = radar_speed_command(declared)
    assert good.findings == [] and set(good.columns["status"]) == {"ok"}


def test_logs_check_of_adc_counts(ground: dict[str, np.ndarray], tmp_path: Path) -> None:
    counts = {k: (v if k == "t" else np.round(v * 2047.0).astype(np.float32)) for k, v in ground.items()}
    bare = [f for f in check_run(_write(tmp_path / "a", counts, BLOCK)) if f.table == "radar_if"]
    assert [f.rule for f in bare] == ["log.radar_full_scale"]  # one finding, not one per sample
    assert bare[0].severity == Severity.ERROR and '"full_scale"' in bare[0].message and "2047" in bare[0].message
    declared = _write(tmp_path / "b", counts, {**BLOCK, "full_scale": 2047.0})
    assert [f for f in check_run(declared) if f.table == "radar_if"] == []
    assert set(radar_speed_command(declared).columns["status"]) == {"ok"}


def test_the_cli_warns_on_stderr_and_keeps_the_csv_clean(ground: dict[str, np.ndarray], tmp_path: Path) -> None:
    import io

    from typer.testing import CliRunner

    from cli.main import app

    folder = _write(tmp_path, conjugated(ground), BLOCK)
    res = CliRunner().invoke(app, ["radar", "speed", str(folder), "--format", "csv"], env={"COLUMNS": "200"})
    assert res.exit_code == 0
    assert "radar.iq_convention" in res.stderr and "i-jq" in res.stderr
    frame = pd.read_csv(io.StringIO(res.stdout))
    assert set(frame["status"]) == {"no_reflections"}  # as declared; the warning says why
