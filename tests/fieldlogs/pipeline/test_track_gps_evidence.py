"""The track evidence's error bounds: the GPS offsets test's evidence (fieldlogs/pipeline/aids/
track_gps.py: the Gauss–Markov covariance by hand, the fixes before a candidate set used as
evidence — an initial position's chain, the track before a split) and the IMU test's looks
(aids/track_imu.py), each keeping Wald's bound on dropping the true track."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gps import TrackGpsAid, gps_llr, quad, quads
from fieldlogs.pipeline.aids.track_gps_initial import TrackGpsInitialAid
from fieldlogs.pipeline.aids.track_imu import LOOK_M, expected_span, heading_llr, kept, look_threshold
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.pipeline.types import Event, Fix, Hypothesis
from schemas.enums import EventType, FixSource
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, net, travel
from tests.fieldlogs.pipeline.test_track_gps_along import _fixes_on

GPS = GpsConfig()


def test_gauss_markov_quadratic_form_hand_computed() -> None:
    # r = (1, 1), σ_w = σ_b = 1. Fixes τ·ln 2 apart: correlation ½, C = [[2, ½], [½, 2]],
    # C⁻¹ = [[2, −½], [−½, 2]] / 3.75, Q = (2 − ½ − ½ + 2) / 3.75 = 0.8.
    tau = 10.0
    t = np.array([0.0, tau * math.log(2.0)])
    assert quad(np.array([1.0, 1.0]), 1.0, 1.0, t, tau) == pytest.approx(0.8)
    # τ = ∞: C = [[2, 1], [1, 2]], Q = (2 − 1 − 1 + 2) / 3 = 2/3 (Sherman–Morrison: (2 − 4/3) / 1)
    assert quad(np.array([1.0, 1.0]), 1.0, 1.0, t) == pytest.approx(2.0 / 3.0)
    # τ = 0: independent fixes, C = 2·I, Q = 1
    assert quad(np.array([1.0, 1.0]), 1.0, 1.0, t, 0.0) == pytest.approx(1.0)
    # rows are candidates: one factorisation, the same Q per row
    assert quads(np.array([[1.0, 1.0], [2.0, 2.0]]), 1.0, 1.0, t, tau) == pytest.approx([0.8, 3.2])


def _start_then_gps(offset: float) -> list[Event]:
    """Crossover network: fixes every second on D1 (``offset`` m left of it, U1 4 m to the
    left), 10 m/s from pos 50; the initial aid starts D1/U1 at t = 4 s (five steady fixes)."""
    n = net("crossover")
    lines = track_lines(n)
    t, lat, lon = _fixes_on("crossover", "D1", [(float(t), 50.0 + 10.0 * t, offset) for t in range(12)])
    aids = [
        TopologyAid(lines, MARGIN),
        TrackGpsInitialAid(t, lat, lon, lines, CFG, GPS),
        TrackGpsAid(t, lat, lon, lines, CFG, GPS),
    ]
    return run_aids(travel(n, np.full(120, 10.0)), aids, MARGIN).events  # type: ignore[arg-type]


def test_the_initial_chain_is_evidence_at_once() -> None:
    # the five chain fixes (t = 0 … 4) dead reckoned back along D1 and U1 (inside both) and the
    # next one (t = 5): Q_D1 ≈ 0, Q_U1 for r = 3.8 m over six fixes (τ = 180 s) — far above Wald's
    # A = ln(0.99/1e-4) = 9.2; D1 at the first fix after the start, not five fixes later
    ev = _start_then_gps(0.2)
    res = [e for e in ev if e.type == EventType.TRACK_RESOLVED]
    assert [e.t for e in ev if e.type == EventType.INITIAL_POSITION_GPS] == [4.0]
    assert len(res) == 1 and res[0].t == 5.0
    assert res[0].detail["track_id"] == "D1" and res[0].detail["evidence"] == "gps" and res[0].detail["fixes"] == 6


def test_fixes_between_the_tracks_decide_nothing() -> None:
    # 2 m from either track for the whole run: no candidate is ever dropped
    ev = _start_then_gps(2.0)
    assert [e.t for e in ev if e.type == EventType.INITIAL_POSITION_GPS] == [4.0]
    assert not [e for e in ev if e.type in (EventType.TRACK_RESOLVED, EventType.HYPOTHESIS_DROPPED)]


def _gauss_markov(rng: np.random.Generator, n: int, runs: int, sigma: float, tau: float) -> np.ndarray:
    phi = math.exp(-1.0 / tau)
    x = np.empty((runs, n))
    x[:, 0] = rng.normal(0.0, sigma, runs)
    for k in range(1, n):
        x[:, k] = phi * x[:, k - 1] + math.sqrt(1.0 - phi * phi) * sigma * rng.normal(0.0, 1.0, runs)
    return x


@pytest.mark.parametrize("prefix", [0, 10])
def test_wald_bound_with_gauss_markov_errors(prefix: int) -> None:
    """Under the model the likelihood ratio of a wrong candidate against the true one is a
    martingale of mean 1, so (Ville's inequality) the chance that it ever reaches e^A is at most
    e^−A = α/(1 − β) — whatever the stopping rule, and with the common fixes before a split
    (identical offsets for both, ``prefix`` of them) in the evidence. Checked by simulation at
    α = 0.05 (A = 2.94): 1 s fixes, σ_b = 0.75 m Gauss–Markov (τ = 180 s) + 0.25 m white, the
    wrong branch diverging from the true one as a 1:9 turnout's lead (x²/2R, R = 190 m, x = 10 m/s·t)
    up to 4 m; the share of runs that ever drop the true track must stay within the bound (plus
    three binomial σ)."""
    rng = np.random.default_rng(31)
    runs, n, alpha, beta = 1500, 20, 0.05, 0.01
    a = math.log((1.0 - beta) / alpha)
    sb, sw, tau = GPS.noise_sigma_m, GPS.noise_white_m, GPS.noise_tau_s
    total = prefix + n
    err = _gauss_markov(rng, total, runs, sb, tau) + rng.normal(0.0, sw, (runs, total))
    x = 10.0 * np.arange(1, n + 1)
    sep = np.concatenate([np.zeros(prefix), np.minimum(x * x / 380.0, 4.0)])
    t = np.arange(total, dtype=float)
    wrong = 0
    for k in range(runs):
        true_r, wrong_r = err[k], err[k] - sep
        for m in range(prefix + 1, total + 1):
            llr = gps_llr(np.vstack([true_r[:m], wrong_r[:m]]), sw, sb, t[:m], tau)
            if llr[1, 0] >= a:
                wrong += 1
                break
            if llr[0, 1] >= a:
                break
    bound = alpha / (1.0 - beta)
    assert wrong / runs <= bound + 3.0 * math.sqrt(bound * (1.0 - bound) / runs)


def _imu_wrong_share(diverging: bool, toe_known: bool = False) -> tuple[float, float]:
    """The IMU test's looks every ``LOOK_M`` past the split (aids/track_imu.py): per look the
    generalised LR against the true branch has mean at most 1 + w·√(2/π)/σ (the span's width w:
    the LR at its near end plus the integral of |∂LR/∂μ|, whose mean is √(2/π)/σ), so with the
    threshold A + ln L + ln(1 + w·√(2/π)/σ) Markov's inequality over the L looks bounds the chance
    of dropping the true branch at one split by e^−A. Simulated at α = 0.05: 1:9 turnout (α_f =
    6.34°, lead 21 m), m = 5 m, the true toe uniform within ±m, 15 m/s, the model's gyro bias,
    white noise and geometry spread (defaults). ``toe_known``: the spans as if the toe lay exactly
    at the dead-reckoned split and A unraised (the test must see that this breaks the bound).
    Returns the share of runs dropping the true branch and the bound (+ three binomial σ)."""
    rng = np.random.default_rng(7)
    runs, alpha, beta, v = 2000, 0.05, 0.01, 15.0
    a = math.log((1.0 - beta) / alpha)
    turn, lead, m = math.atan(1.0 / 9.0), 190.0 * math.atan(1.0 / 9.0), 5.0
    c = CFG
    looks = math.ceil((lead + m) / LOOK_M)
    wrong = 0
    for _ in range(runs):
        e = rng.uniform(-m, m)
        bias = math.radians(c.gyro_bias_dps) * rng.normal()
        geo = math.radians(c.heading_geometry_deg) * rng.normal()
        white, before = 0.0, 0.0
        for k in range(1, looks + 1):
            x = min(k * LOOK_M, lead + m)
            dur = (x + m) / v  # the window [split − m, split + x]
            white += math.radians(c.gyro_noise_dps_rthz) * math.sqrt(dur - before) * rng.normal()  # a random walk
            before = dur
            true = turn * min(max((x - e) / lead, 0.0), 1.0) if diverging else 0.0
            dpsi = true + bias * dur + geo + white
            sigma = math.sqrt(
                (math.radians(c.gyro_bias_dps) * dur) ** 2
                + math.radians(c.gyro_noise_dps_rthz) ** 2 * dur
                + math.radians(c.heading_geometry_deg) ** 2
            )
            mm = 0.0 if toe_known else m
            spans = [expected_span(turn, lead, x, mm), expected_span(0.0, lead, x, mm)]
            keep = kept(heading_llr(dpsi, spans, sigma), a if toe_known else look_threshold(a, looks, spans, sigma))
            if len(keep) == 1:
                wrong += keep != [0 if diverging else 1]
                break
    bound = alpha / (1.0 - beta)
    return wrong / runs, bound + 3.0 * math.sqrt(bound * (1.0 - bound) / runs)


@pytest.mark.parametrize("diverging", [False, True])
def test_wald_bound_with_imu_looks(diverging: bool) -> None:
    share, bound = _imu_wrong_share(diverging)
    assert share <= bound


def test_imu_looks_ignoring_the_toes_uncertainty_break_the_bound() -> None:
    share, bound = _imu_wrong_share(True, toe_known=True)
    assert share > bound


def test_a_split_keeps_each_lineages_offsets() -> None:
    # before: D1 and U1 ambiguous (lineages 7 and 8) with two fixes of evidence between them;
    # W1 splits D1 into D2 and X1 (new lineages 9, 10, came from D1's end), U1 runs on (8):
    # the branches take D1's offsets, U1 keeps its own — the evidence against U1 is not lost
    lines = track_lines(net("crossover"))
    aid = TrackGpsAid(np.zeros(0), np.zeros(0), np.zeros(0), lines, CFG, GPS)
    aid.times, aid.cols, aid.tracks = [1.0, 2.0], {7: [0.1, 0.2], 8: [-3.9, -3.8]}, {7: "D1", 8: "U1"}
    hyps = (
        Hypothesis("D2", 1.0, 1, hid=9, switch_id="W1", split_d=10.0, came_from=("D1", "end")),
        Hypothesis("X1", 1.0, 1, hid=10, switch_id="W1", split_d=10.0, came_from=("D1", "end")),
        Hypothesis("U1", 300.0, 1, hid=8),
    )
    fix = Fix(3.0, 0.0, 0.0, math.nan, math.nan, "", "", 1, FixSource.GPS, 1.0, hyps=hyps)
    aid._begin(fix, SimpleNamespace(t=3.0))  # type: ignore[arg-type]
    assert aid.times == [1.0, 2.0]
    assert aid.cols == {9: [0.1, 0.2], 10: [0.1, 0.2], 8: [-3.9, -3.8]}
    assert aid.set_t == 3.0 and aid.tracks == {9: "D2", 10: "X1", 8: "U1"}
