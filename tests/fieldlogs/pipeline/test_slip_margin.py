"""A slip/slide correction the odometry cannot trust turns the position uncertain (S000's
fail-safe; bench/NOTES.md, "Slip margin").

* Hand-built (``test_odometry``'s exact kinematics, 3 cm pulses): a 15 s slip fails safe; a slide
  that begins while the detection signal of the slip's end is still up is only detected at
  its end lobe, with its start point inside the slide — |θ̄| beyond arcsin(Ta/G). That
  correction fails safe at its start: the distance stays on the pulses, no eq. 13 budget.
* :class:`FailsafeAid`: its moments (fail-safes and the detections after them) and reasons.
* Wheel scale: divided out only on a fit with ≥ 2 residual degrees of freedom.
* Regression, seeded simulator: the network sample, route 0420-U2 → U3 → U4 → X2 → D5 → D6 at
  60 km/h, IMU-only, seed 2. A balise group made the position determined during the slide
  that began inside a fail-safe watch; the slide's end-lobe correction, started on sliding
  pulses (v0 10.2 m/s against 15.4 true), took 63 m off 10 s of travel against eq. 13's
  22.8 m and claimed U3 on U4 and U4 on X2 for 29 cycles on adf26d4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np
import pytest

from dbtools.database import read_network
from fieldlogs.pipeline.aid import EngineView
from fieldlogs.pipeline.aids.failsafe import FailsafeAid
from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.consistency import BaliseEvidence, Interval, fit_evidence
from fieldlogs.pipeline.odometry.correct import correct_odometry
from fieldlogs.pipeline.odometry.start_point import ta_end_lobe
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.track_truth import compare_tracks
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.pipeline.types import Fix, SlipEpisode
from fieldlogs.pipeline.wheelscale import MIN_RESCALE_DOF
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.enums import EventType, FixSource, PositionState
from tests.bench.scripts import load_script
from tests.fieldlogs.pipeline.test_odometry import Scenario, scenario, slip_pulse

CFG = OdometryConfig()


def slip_then_slide() -> Scenario:
    """From 3 m/s: +0.5 m/s² up to 20 s, then −0.5 m/s²; the wheel +30 % over 5–20 s (a slip
    longer than the maximum correction time), −30 % over 22–28 s (a slide)."""

    def wheel(t: np.ndarray) -> np.ndarray:
        return slip_pulse(5.0, 15.0, 0.3, edge=0.5)(t) + slip_pulse(22.0, 6.0, -0.3, edge=0.5)(t)

    return scenario(60.0, lambda t: np.where(t < 20.0, 0.5, -0.5), 3.0, slip=wheel, ax_noise_kmh_s=0.1)


def test_a_correction_from_a_sliding_start_point_fails_safe_at_its_start() -> None:
    sc = slip_then_slide()
    odo = correct_odometry(sc.cycles, CFG)
    assert odo.diagnostics is not None
    slip, slide = odo.episodes
    # the slip: no jerk-quiet start point after the warm-up, but the look-back point (4.9 s,
    # before the onset) is flagged by neither criterion — trusted, corrected for 10 s
    assert not slip.start_found and slip.start_trusted
    assert slip.failsafe and slip.t_end - slip.t_start == pytest.approx(CFG.max_correction_s)
    # the slide's onset fell in the slip's watch (a detection after the fail-safe)
    assert slip.watch is not None and slip.after_failsafe_t and slip.t_end < slip.after_failsafe_t[0] < slip.watch.end_t
    # the slide, found at its end lobe 28.3 s, starts 3.4 s earlier inside it: θ̄ clipped
    assert slide.t_detect == pytest.approx(28.3) and 22.0 < slide.t_start < 28.0
    assert odo.diagnostics.episodes[1].theta_clipped
    assert not slide.start_trusted and slide.failsafe
    # its end lobe (the wheel re-accelerating, K·a_x − K·A_p < 0, a slip's sign) follows the
    # slide's onset lobe (> 0, flagged until 27.x s): the kind is the onset's (eq. 1's lobe rule)
    assert odo.diagnostics.episodes[1].diff_at_detect_kmh_s < 0
    assert (slip.kind, slide.kind) == ("slip", "slide")
    # a fail-safe at its start: no corrected cycle, no eq. 13 budget, the distance on the pulses
    assert slide.t_end == slide.t_start and slide.i_end == slide.i_start
    assert slide.max_error_m == 0.0 and slide.d_corrected_m == slide.d_pulse_m == 0.0
    assert not odo.slipping[slide.i_start :].any()
    after = slice(slip.i_end, None)
    off = odo.d[after] - sc.cycles.d_pulse[after]
    np.testing.assert_allclose(off, off[0], atol=1e-9)
    # the watch from the start grows the allowance by |inertial − pulse speed| + Δa·t
    assert slide.watch is not None and slide.watch.allowance_m > 0.0
    assert slide.after_failsafe_t == ()  # its own detection is not one after its fail-safe


def eq1_lobes(end_peak: float, *, opp_last: int = 139, between: bool = False) -> bool:
    """``ta_end_lobe`` on hand-built K·a_x − K·A_p (0.1 s cycles, Ta 0.34 m/s², H 40 and M 39
    cycles: the window reaches 79 cycles back): +1.5 m/s² on cycles 100 … ``opp_last``, the
    detected lobe −``end_peak`` on 141 … 180 (its onset, cycle 141); ``between``: a lobe of
    −0.5 on 128 … 130 (the detected lobe's sign) after the opposite one."""
    diff = np.zeros(300)
    diff[100 : opp_last + 1] = 1.5
    diff[141:181] = -end_peak
    if between:
        diff[128:131] = -0.5
    return ta_end_lobe(diff, np.abs(diff) > 0.34, 141, 40, 39)


def test_eq1_end_lobe_takes_the_kind_of_the_lobe_before_it() -> None:
    assert eq1_lobes(1.5)  # a slide's onset, then its end: the kind is reversed
    assert eq1_lobes(4.0 * 1.5)  # LOBE_RATIO × the opposite peak still one disturbance's end
    assert not eq1_lobes(6.01)  # a far deeper lobe is a new disturbance: its own sign
    assert eq1_lobes(1.5, opp_last=120)
    assert not eq1_lobes(1.5, opp_last=120, between=True)  # the latest flagged lobe has its sign: an onset
    # the window: cycles 141 − 79 = 62 … 140
    assert eq1_lobes(1.5, opp_last=100)
    diff = np.zeros(300)
    diff[50:63] = 1.5
    diff[141:181] = -1.5
    assert ta_end_lobe(diff, np.abs(diff) > 0.34, 141, 40, 39)  # its last cycle 62 inside
    diff[62] = 0.0
    assert not ta_end_lobe(diff, np.abs(diff) > 0.34, 141, 40, 39)  # ends at 61: outside
    assert not ta_end_lobe(-diff, np.abs(diff) > 0.34, 141, 40, 39)
    # the opposite lobe (100 … 120) itself follows a lobe of the detected sign (60 … 70, within
    # 79 cycles before cycle 100): it ended an earlier disturbance, the detection is an onset
    diff = np.zeros(300)
    diff[60:71], diff[100:121], diff[141:181] = -1.5, 1.5, -1.5
    assert not ta_end_lobe(diff, np.abs(diff) > 0.34, 141, 40, 39)
    diff[60:71] = 1.5  # of the opposite lobe's sign: no matter
    assert ta_end_lobe(diff, np.abs(diff) > 0.34, 141, 40, 39)


@dataclass
class View:
    """The parts of an :class:`EngineView` ``FailsafeAid`` reads."""

    t: float
    km: float
    d: float
    estimate: Fix | None


def episode(t_start: float, t_end: float, *, trusted: bool = True, again: tuple[float, ...] = ()) -> SlipEpisode:
    return SlipEpisode(
        "slide", t_start + 2.0, t_start, t_end, 0, 0, 0.0, 0.0, 0.0, False, True,
        criterion="ta", start_found=trusted, theta0_rad=0.0, v0_mps=10.0, start_trusted=trusted, after_failsafe_t=again,
    )  # fmt: skip


def test_failsafe_aid_moments_and_reasons() -> None:
    eps = [episode(20.0, 30.0, again=(31.0, 45.0)), episode(52.5, 52.5, trusted=False)]
    aid = FailsafeAid(eps)
    moments = [(o.t, o.payload[1]) for o in aid.observations()]
    assert moments == [(30.0, False), (31.0, True), (45.0, True), (52.5, False)]
    fix = Fix(44.0, 100.0, 100.0, 1000.0, 1000.0, "L", "D", 1, FixSource.BALISE, 2.0)
    uncertain = Fix(44.0, 100.0, 100.0, 1000.0, 1000.0, "L", "D", 1, FixSource.BALISE, 2.0, PositionState.UNCERTAIN)
    obs = list(aid.observations())

    def outcome(i: int, est: Fix | None) -> tuple[list[str], Fix | None]:
        out = aid.observe(obs[i], cast(EngineView, View(obs[i].t, 1010.0, 110.0, est)))
        return [e.detail["reason"] for e in out.events if e.type == EventType.FAILSAFE], out.estimate

    reasons, est = outcome(0, fix)
    assert reasons == ["slip/slide correction exceeded the maximum correction time"]
    assert est is not None and est.state == PositionState.UNCERTAIN and est.uncertain_since_d == 110.0
    # a detection after the fail-safe: uncertain again where a fix made it determined ...
    reasons, est = outcome(2, fix)
    assert reasons == ["slip/slide detected again after a fail-safe, with no room for a correction"]
    assert est is not None and est.state == PositionState.UNCERTAIN
    # ... nothing where it is uncertain already or there is no position
    assert outcome(1, uncertain) == ([], None)
    assert outcome(1, None) == ([], None)
    reasons, _ = outcome(3, fix)
    assert reasons == ["slip/slide correction from a start point that was not adhering"]


def test_seed_2_slide_after_a_failsafe_claims_no_wrong_track(sample_network_db: Path, tmp_path: Path) -> None:
    net = read_network(sample_network_db)
    sc = load_script("slip_margin_scan").route_scenario(2)
    streams, meta = simulate_run(net, scenario_from_dict(sc, source="test"))
    res = run_pipeline(read_run(write_run(tmp_path / "run", meta, streams)), net)
    truth = streams["truth"]
    assert int(compare_tracks(res.positions, truth, net)["wrong"].sum()) == 0  # 29 cycles on adf26d4
    det = res.positions["state"].to_numpy(dtype=object) == PositionState.DETERMINED.value
    assert compare_with_truth(res.positions, truth)["within_margin"].to_numpy(dtype=bool)[det].all()
    # the correction that removed 63 m: from a sliding start point, now a fail-safe at its start
    # the episodes' kinds are the simulated ones' (slip 21.9–32.9 s, slide 50.3–54.6, slide
    # 102.8–107.3): the slide found at its end lobe (54.9 s) was a slip on fa5c627
    sim = meta.extra["sim_truth"]["slip_episodes"]
    assert [e["kind"] for e in sim] == ["slip", "slide", "slip", "slide"]
    assert [(e.kind, e.t_detect) for e in res.odometry.episodes] == [("slip", 23.9), ("slide", 54.9), ("slide", 103.7)]
    bad = [e for e in res.odometry.episodes if not e.start_trusted]
    assert [(e.t_start, e.t_end, e.t_detect) for e in bad] == [(52.5, 52.5, 54.9)]
    ev = res.events[res.events["type"] == EventType.FAILSAFE.value]
    at = dict(zip(ev["t"].round(3), ev["detail"].str.extract(r'"reason": "([^"]+)"')[0], strict=True))
    # the slide's onset at 51.5 s, inside the first slip's watch, after the balise group at 51.2 s
    assert at[51.5] == "slip/slide detected again after a fail-safe, with no room for a correction"
    assert at[52.5] == "slip/slide correction from a start point that was not adhering"
    kinds = dict(zip(ev["t"].round(3), ev["detail"].str.extract(r'"kind": "([^"]+)"')[0], strict=True))
    assert kinds[52.5] == "slide"
    slips = res.events[res.events["type"].isin([EventType.SLIP.value, EventType.SLIDE.value])]
    assert slips["type"].tolist() == ["slip", "slide", "slide"]
    state = res.positions.set_index(res.positions["t"].round(3))["state"]
    assert state[51.4] == PositionState.DETERMINED.value
    assert state[51.5] == PositionState.UNCERTAIN.value
    # the slide's own watch (from 49.4 s, before its onset) grows the margin until the
    # candidates span U3's end: no claim until the next balise group
    assert (state.loc[51.5:74.0] != PositionState.DETERMINED.value).all()


@pytest.mark.parametrize(
    "seed",
    [
        # a slide inside a fail-safe watch left uncorrected; two balise intervals (slip budgets 56
        # and 102 m) fitted the wheel −4.98 ± 1.13 % on one residual: divided out, 153 determined
        # cycles beyond their margin on adf26d4
        26,
        # the watch of the slide detected after the fail-safe agreed at once (from before the
        # onset): 15 uncertain/ambiguous cycles beyond their margin before the watch waited
        107,
    ],
)
def test_route_seeds_hold_their_margin(sample_network_db: Path, tmp_path: Path, seed: int) -> None:
    net = read_network(sample_network_db)
    sc = load_script("slip_margin_scan").route_scenario(seed)
    streams, meta = simulate_run(net, scenario_from_dict(sc, source="test"))
    res = run_pipeline(read_run(write_run(tmp_path / "run", meta, streams)), net)
    cmp = compare_with_truth(res.positions, streams["truth"])
    assert cmp["claimed"].sum() > 500
    assert cmp["within_margin"].all()  # every claimed cycle, uncertain and ambiguous ones included
    scale = res.events[res.events["type"] == EventType.WHEEL_SCALE.value]["detail"]
    assert not scale.str.contains("pulse distance divided").any()  # the fit widens the margin instead
    assert scale.str.contains("margin's distance share widened").all()


def test_a_scale_is_divided_out_only_with_two_residual_degrees_of_freedom() -> None:
    def fit(n: int, params: int) -> BaliseEvidence:
        return BaliseEvidence(-0.05, 0.01, 0.0, float("inf") if params == 1 else 0.2, n, 0.05, params=params)

    assert fit(2, 1).residual_dof == 1  # the scale alone on two intervals
    assert fit(3, 1).residual_dof == 2
    assert fit(4, 2).residual_dof == 2  # scale and lag on four
    assert MIN_RESCALE_DOF == 2


def test_the_fit_carries_its_parameter_count() -> None:
    def iv(dist_m: float, dv_mps: float, along_m: float) -> Interval:
        return Interval(0.0, 1.0, dist_m, along_m, dv_mps)

    # no speed change between the balises: the scale alone, 1 parameter (σ_L infinite)
    alone = fit_evidence([iv(d, 0.0, -0.01 * d) for d in (1000.0, 2000.0, 1500.0, 500.0)])
    assert alone is not None and alone.params == 1 and math.isinf(alone.lag_sigma_s)
    assert alone.residual_dof == 3 and alone.scale == pytest.approx(-0.01)
    # speed changes: scale and lag, 2 parameters (a = −0.01·D + 0.5·Δv)
    rows = [(1000.0, 2.0), (2000.0, -3.0), (1500.0, 1.0), (500.0, 4.0)]
    both = fit_evidence([iv(d, dv, -0.01 * d + 0.5 * dv) for d, dv in rows])
    assert both is not None and both.params == 2 and math.isfinite(both.lag_sigma_s)
    assert both.residual_dof == 2 and both.scale == pytest.approx(-0.01) and both.lag_s == pytest.approx(0.5)
