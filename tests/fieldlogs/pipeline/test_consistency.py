"""Wheel scale and balise clock from the balise corrections (fieldlogs.pipeline.consistency):
the fit and the margin growth by hand, and on the sample run with its wheel turned."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from fieldlogs.io import read_run
from fieldlogs.pipeline.config import ClockConfig, MarginConfig, PipelineConfig
from fieldlogs.pipeline.consistency import Interval, fit_evidence, scale_rate
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.wheelscale import scaled_cycles

SAMPLE = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs" / "sim-d-slips"


def _intervals(e: float, lag: float, allowance: float = 0.0) -> list[Interval]:
    dist = [1000.0, 200.0, 1500.0, 300.0, 800.0]
    dv = [5.0, -6.0, 4.0, -8.0, 2.0]
    return [Interval(0.0, 1.0, d, e * d + lag * v, v, allowance) for d, v in zip(dist, dv, strict=True)]


@pytest.mark.parametrize(("e", "lag"), [(0.05, 0.0), (0.0, 2.0), (-0.03, -1.5), (0.001, 0.3)])
def test_fit_recovers_scale_and_a_late_or_early_balise_clock(e: float, lag: float) -> None:
    """a = e·D + L·Δv exactly (no noise): the fit returns e and L, with σ ≈ 0. A late clock
    (L > 0) makes the correction after a speed-up positive: 2 s late, 5 m/s faster at the
    second balise → the estimate is 10 m ahead there (interval 1: 0·1000 + 2·5 = 10 m)."""
    ev = fit_evidence(_intervals(e, lag))
    assert ev is not None and ev.n == 5
    assert ev.scale == pytest.approx(e, abs=1e-12)
    assert ev.lag_s == pytest.approx(lag, abs=1e-9)
    assert ev.lag_sigma_s < 1e-6
    if lag == 2.0:
        assert _intervals(e, lag)[0].along_m == pytest.approx(10.0)


def test_few_intervals_fit_the_scale_alone() -> None:
    # two intervals 1000 m and 500 m with 30 m and 15 m: e = (1000·30 + 500·15)/(1000² + 500²) = 0.03
    ivs = [Interval(0, 1, 1000.0, 30.0, 3.0), Interval(1, 2, 500.0, 15.0, -3.0)]
    ev = fit_evidence(ivs)
    assert ev is not None and ev.scale == pytest.approx(0.03) and ev.lag_s == 0.0
    assert ev.lag_sigma_s == float("inf")
    assert fit_evidence(ivs[:1]) is None


def test_scale_rate_by_hand() -> None:
    """r_j = (|a_j − L·Δv_j| − 2·u_fix − ΔA_j) / D_j, the largest, never negative."""
    # 5 % over 1000 m = 50 m; fixes 1 m each: (50 − 2)/1000 = 4.8 %
    assert scale_rate([Interval(0, 1, 1000.0, 50.0, 0.0)], 1.0) == pytest.approx(0.048)
    # a slip budget of 20 m accrued on the way holds 20 m of it: (50 − 2 − 20)/1000 = 2.8 %
    assert scale_rate([Interval(0, 1, 1000.0, 50.0, 0.0, 20.0)], 1.0) == pytest.approx(0.028)
    # the worst of two; a 200 m stretch with −12 m: (12 − 2)/200 = 5 %
    ivs = [Interval(0, 1, 1000.0, 50.0, 0.0), Interval(1, 2, 200.0, -12.0, 0.0)]
    assert scale_rate(ivs, 1.0) == pytest.approx(0.05)
    # a 2 s late clock, 5 m/s faster at the end: 10 m of the correction are the clock's
    assert scale_rate([Interval(0, 1, 1000.0, 10.0, 5.0)], 1.0, lag_s=2.0) == 0.0
    # within the fixes' noise: no scale error at all
    assert scale_rate([Interval(0, 1, 1000.0, 1.5, 0.0)], 1.0) == 0.0
    assert scale_rate([], 1.0) == 0.0


def _turned_wheel(tmp_path: Path, factor: float) -> Path:
    run = tmp_path / "run"
    shutil.copytree(SAMPLE, run)
    tacho = pd.read_parquet(run / "tacho.parquet")
    tacho["pulses"] = (tacho["pulses"] * factor).round().astype("int64")
    tacho.to_parquet(run / "tacho.parquet", index=False)
    return run


def test_a_turned_wheel_widens_the_margin_never_below_the_configured_share(sample_db: Path, tmp_path: Path) -> None:
    """Without the rescaling (``margin.wheel_rescale`` off) the wheel's scale widens the margin."""
    network = read_network(sample_db)
    run = _turned_wheel(tmp_path, 1.05)
    off = replace(PipelineConfig(), clock=ClockConfig(max_lag_s=0.0), margin=MarginConfig(scale_check_pct=1000.0))
    before = run_pipeline(read_run(run), network, off)
    after = run_pipeline(read_run(run), network, replace(PipelineConfig(), margin=MarginConfig(wheel_rescale=False)))
    ev = after.events[after.events["type"] == "wheel_scale"]
    assert len(ev) == 1
    detail = json.loads(ev["detail"].iloc[0])
    # the worst stretch's scale error is added to the configured 2 %
    assert detail["distance_pct"] == pytest.approx(2.0 + detail["largest_interval_scale_pct"], abs=2e-3)
    assert 3.5 < detail["largest_interval_scale_pct"] < 5.5  # 5 % less the fixes' 2 m on 208 m
    assert "wheel scale" in after.summary["warnings"][0]
    m0, m1 = before.positions["margin_m"].to_numpy(), after.positions["margin_m"].to_numpy()
    ok = np.isfinite(m0) & np.isfinite(m1)
    assert (m1[ok] >= m0[ok] - 1e-9).all() and (m1[ok] > m0[ok]).any()
    assert before.summary["truth"]["within_margin_share"] < 0.9  # claimed cycles: 75 % within
    assert after.summary["truth"]["within_margin_share"] >= 0.999


def test_a_clean_run_gets_no_warning(sample_db: Path) -> None:
    res = run_pipeline(read_run(SAMPLE), read_network(sample_db))
    assert res.summary["warnings"] == []
    assert not res.events["type"].isin(["wheel_scale", "balise_clock", "clock_offset"]).any()


def test_scaled_cycles_divide_the_pulse_distance_and_speed_by_hand() -> None:
    """Pulses 5 % over the declared wheel: 105 m by pulses are 100 m, 21 m/s are 20 m/s; the
    counts (and everything else) stay."""
    one = np.ones(2)
    cyc = Cycles(
        t=np.array([0.0, 0.1]),
        pulses=np.array([0.0, 100.0]),
        d_pulse=np.array([0.0, 105.0]),
        v_pulse=np.array([0.0, 21.0]),
        imu={"ax": one},
        cab=np.ones(2, dtype=np.int8),
        pto=np.ones(2, dtype=np.int8),
        has_tacho=True,
        has_imu=True,
    )
    out = scaled_cycles(cyc, 1.05)
    assert out.d_pulse == pytest.approx([0.0, 100.0]) and out.v_pulse == pytest.approx([0.0, 20.0])
    assert out.pulses is cyc.pulses and out.imu is cyc.imu and cyc.d_pulse[1] == 105.0


@pytest.mark.parametrize("factor", [1.05, 1.02, 0.95])
def test_a_turned_wheel_is_divided_out_and_keeps_the_clean_runs_margins(
    factor: float, sample_db: Path, tmp_path: Path
) -> None:
    """The balise intervals' scale is divided out of the pulses and the run replayed (module
    :mod:`fieldlogs.pipeline.wheelscale`): one ``wheel_scale`` event with the scale found
    (+5 %: 2.49 % then 2.10 % → 4.64 %; the slip corrections run part of the long intervals
    on the radar, so one fit sees only part of it), no widening left, the margins and the
    determined cycles of the clean run, and the radar's wheel calibration still stated against
    run.json's diameter. Before: the margin widened to 5.9 / 4.2 / 6.2 % of the distance
    (mean margin 34.5 / 33.5 / 33.5 m, clean 18.8 m) and 1,484 cycles fewer determined at ±5 %."""
    network = read_network(sample_db)
    clean = run_pipeline(read_run(SAMPLE), network)
    res = run_pipeline(read_run(_turned_wheel(tmp_path, factor)), network)
    ev = res.events[res.events["type"] == "wheel_scale"]
    assert len(ev) == 1
    detail = json.loads(ev["detail"].iloc[0])
    assert detail["scale_pct"] == pytest.approx(100.0 * (factor - 1.0), abs=0.5)
    assert "distance_pct" not in detail and "wheel scale" in res.summary["warnings"][0]
    det0 = (clean.positions["state"] == "determined").to_numpy()
    det1 = (res.positions["state"] == "determined").to_numpy()
    assert det1.sum() >= det0.sum() - 5
    m0 = float(clean.positions["margin_m"][det0].mean())
    assert float(res.positions["margin_m"][det1].mean()) < m0 + 1.0
    assert res.summary["truth"]["within_margin_share"] >= 0.999
    cal0, cal1 = clean.summary["wheel_calibration"], res.summary["wheel_calibration"]
    assert cal1["ratio"] == pytest.approx(cal0["ratio"] / factor, rel=2e-3)


def test_a_clock_is_judged_on_the_corrected_wheel(sample_db: Path, tmp_path: Path) -> None:
    """Wheel +5 % and the balise clock 1 s late: before, the clock was never judged (|ê| 2.5 %
    beyond the scale check; 74.8 % of the determined cycles within margin); now the scale is
    divided out first and the clock found on the corrected replay (0.98 s late)."""
    network = read_network(sample_db)
    run = _turned_wheel(tmp_path, 1.05)
    tel = pd.read_parquet(run / "balise.parquet")
    tel.assign(t=tel["t"] + 1.0).to_parquet(run / "balise.parquet", index=False)
    res = run_pipeline(read_run(run), network)
    kinds = list(res.events["type"][res.events["type"].isin(["wheel_scale", "balise_clock"])])
    assert sorted(kinds) == ["balise_clock", "wheel_scale"]
    clock = json.loads(res.events["detail"][res.events["type"] == "balise_clock"].iloc[0])
    assert clock["offset_s"] == pytest.approx(1.0, abs=0.1)
    assert res.summary["truth"]["within_margin_share"] >= 0.999
