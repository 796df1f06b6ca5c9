"""GPS unit (SPEC §5.4, [S001 §4.2]): trust filter, map-matched km/offset, up/down
decision, crossover — on hand-made fix sequences along the synthetic demo line.

Fixes are generated here (not by the simulator): the true position on a track from the
alignment (``spec.alignment.xy(s, TRACK_OFFSETS[track])``), plus a Gauss-Markov (AR(1))
error per axis, white noise, multipath bursts (a step of J metres in a random direction
for a few seconds) and outages (NaN lat/lon, fix 0).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from dbtools.gis.geometry import Projector
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.gps.analysis import DECIDED_COLUMNS, FIX_COLUMNS, analyse_gps
from fieldlogs.pipeline.gps.evidence import mean_variance_factor
from fieldlogs.pipeline.gps.trust import trust_filter
from fieldlogs.simulate.networks.synthetic import TRACK_OFFSETS, build_network, demo_line

P = Projector(9)
SPEC = demo_line()
NET = build_network([SPEC], P)
A = SPEC.alignment
CFG = GpsConfig()


def model(sigma: float) -> GpsConfig:
    """The default configuration with its error model matching the generated noise."""
    return replace(CFG, noise_sigma_m=sigma, noise_tau_s=60.0)


def ar1(rng: np.random.Generator, n: int, sigma: float, tau: float) -> np.ndarray:
    phi = np.exp(-1.0 / tau)
    w = rng.normal(0.0, sigma * np.sqrt(1 - phi * phi), n)
    e = np.empty(n)
    e[0] = rng.normal(0.0, sigma)
    for k in range(1, n):
        e[k] = phi * e[k - 1] + w[k]
    return e


def fixes(
    rng: np.random.Generator,
    *,
    track: str = "D",
    direction: int = 1,
    km0: float = 3000.0,
    speed: float = 20.0,
    seconds: int = 150,
    sigma: float = 0.75,
    tau: float = 60.0,
    white: float = 0.2,
    lateral: float = 0.0,
    bursts: tuple[tuple[float, float, float], ...] = (),
    outages: tuple[tuple[float, float], ...] = (),
    crossover: tuple[float, float, str] | None = None,
    bias_along_m: float = 0.0,
) -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """(gps frame, true km, mask of burst fixes). ``crossover`` = (t start, length m, to track);
    ``bias_along_m``: a constant plane error along the track's heading at the first fix."""
    t = np.arange(seconds, dtype=float)
    km = km0 + direction * speed * t
    off = np.full(t.size, TRACK_OFFSETS[track] + lateral)
    if crossover is not None:
        t_c, length, to = crossover
        frac = np.clip((t - t_c) * speed / length, 0.0, 1.0)
        off = off + frac * (TRACK_OFFSETS[to] - TRACK_OFFSETS[track])
    s = A.chainage(km)
    x0, y0 = A.xy(s)
    h = A.heading(s)
    x = x0 - off * np.sin(h)
    y = y0 + off * np.cos(h)
    x = x + bias_along_m * np.cos(h[0])
    y = y + bias_along_m * np.sin(h[0])
    if sigma > 0:
        x = x + ar1(rng, t.size, sigma, tau)
        y = y + ar1(rng, t.size, sigma, tau)
    if white > 0:
        x = x + rng.normal(0, white, t.size)
        y = y + rng.normal(0, white, t.size)
    burst = np.zeros(t.size, dtype=bool)
    for t0, dur, mag in bursts:
        a = rng.uniform(0, 2 * np.pi)
        m = (t >= t0) & (t < t0 + dur)
        x[m] += mag * np.cos(a)
        y[m] += mag * np.sin(a)
        burst |= m
    fix = np.full(t.size, 2)
    for a0, a1 in outages:
        m = (t >= a0) & (t < a1)
        x[m] = np.nan
        y[m] = np.nan
        fix[m] = 0
    lon, lat = P.to_lonlat(x, y)
    frame = pd.DataFrame({"t": t, "lat": lat, "lon": lon, "fix": fix, "nsat": 10, "hdop": 0.9})
    return frame, km, burst


# ------------------------------------------------------------------------ stream handling


def test_missing_or_empty_stream_gives_empty_analysis():
    for gps in (None, pd.DataFrame(columns=["t", "lat", "lon", "fix", "nsat", "hdop"])):
        res = analyse_gps(gps, NET, CFG)
        assert res.decisions == [] and res.crossovers == []
        assert len(res.fixes) == 0
        cols = list(res.fixes.columns)
        assert cols[: len(FIX_COLUMNS)] == list(FIX_COLUMNS)
        assert {"rms_5", "rms_15", "rms_30", *DECIDED_COLUMNS} <= set(cols)


def test_output_columns_sorting_and_usable_fixes():
    gps, _, _ = fixes(np.random.default_rng(0), seconds=60)
    gps.loc[10, "fix"] = 1  # no differential correction
    gps.loc[20, "hdop"] = 9.9
    gps.loc[30, "hdop"] = np.nan  # unknown HDOP is no reason to drop a fix
    shuffled = pd.concat([gps.iloc[::-1], gps.iloc[[40]]], ignore_index=True)  # unsorted + a duplicate t
    f = analyse_gps(shuffled, NET, CFG).fixes
    assert len(f) == 61 and f["t"].is_monotonic_increasing
    for c in (
        "t",
        "lat",
        "lon",
        "fix",
        "trusted",
        "line_code",
        "track",
        "km_m",
        "offset_m",
        "rms_5",
        "rms_15",
        "rms_30",
    ):
        assert c in f.columns
    assert not f.loc[f["t"] == 10, "usable"].any() and not f.loc[f["t"] == 20, "usable"].any()
    assert f.loc[f["t"] == 30, "usable"].all()
    assert f.loc[f["t"] == 40, "usable"].sum() == 1  # the repeated time stamp is not used twice
    # an unusable fix cuts the run: the next fixes are untrusted until 5 s of history
    assert not f.loc[(f["t"] > 10) & (f["t"] < 15), "trusted"].any()
    assert f.loc[(f["t"] >= 16) & (f["t"] < 20), "trusted"].all()


def test_trust_statistic_by_hand():
    """Constant velocity and constant acceleration give RMS 0; one fix displaced by 5 m
    gives second differences (0, …, +5, −10, +5): RMS over 5 values √(150/5 − 0²) = √30."""
    t = np.arange(40, dtype=float)
    usable = np.ones(t.size, dtype=bool)
    for x in (20.0 * t, 20.0 * t + 0.5 * 0.8 * t * t):
        trusted, rms = trust_filter(t, x, np.zeros(t.size), usable, CFG)
        assert np.nanmax(rms[30]) < 1e-6 and trusted[5:].all() and not trusted[:5].any()
    x = 20.0 * t
    x[20] += 5.0
    trusted, rms = trust_filter(t, x, np.zeros(t.size), usable, CFG)
    assert rms[5][22] == pytest.approx(np.sqrt(30.0))
    assert not trusted[20:22].any()  # the jump itself (|a| = 5 > 3 m) and the step back
    assert not trusted[20:50].any()  # … and every fix whose 30 s window contains them
    assert trusted[5:20].all()


def test_mean_variance_factor():
    assert mean_variance_factor(1, 0.9) == pytest.approx(1.0)
    assert mean_variance_factor(np.array([4.0]), 0.0)[0] == pytest.approx(0.25)
    rho = np.exp(-1 / 60)
    brute = np.mean(rho ** np.abs(np.subtract.outer(np.arange(120), np.arange(120))))
    assert mean_variance_factor(120, rho) == pytest.approx(brute)
    assert 1 / mean_variance_factor(120, rho) == pytest.approx(1.76, abs=0.01)  # effective sample size


# ------------------------------------------------------------------------ km and offsets


def test_noise_free_km_offset_and_sign_including_curves():
    c = max(A.curves, key=lambda c: c.arc_m)  # run through the longest curve
    km0 = float(A.km(c.start_m)) - 100.0
    for lateral in (0.0, 1.0):
        gps, km, _ = fixes(np.random.default_rng(0), km0=km0, speed=10.0, sigma=0.0, white=0.0, lateral=lateral)
        f = analyse_gps(gps, NET, CFG).fixes
        assert (f["track"] == "D").all()
        assert np.max(np.abs(f["km_m"] - km)) < 0.5
        assert np.max(np.abs(f["offset_m"] - lateral)) < 0.2  # 1 m left of D → +1 m
        assert f["trusted"].iloc[5:].all()


# ------------------------------------------------------------------------ decisions


@pytest.mark.parametrize("track", ["D", "U"])
@pytest.mark.parametrize("direction", [1, -1])
def test_decision_on_both_tracks_and_directions(track, direction):
    cfg = model(0.5)
    gps, km, _ = fixes(np.random.default_rng(7), track=track, direction=direction, sigma=0.5, km0=6000.0)
    res = analyse_gps(gps, NET, cfg)
    assert len(res.decisions) == 1
    d = res.decisions[0]
    assert (d.line_code, d.track, d.km_dir) == ("0900", track, direction)
    assert d.t <= 30.0
    assert d.km_m == pytest.approx(km[int(d.t)], abs=5.0)
    ev = d.evidence
    assert ev["n_fixes"] >= cfg.decide_min_fixes and ev["share"] >= cfg.decide_min_share
    assert {"mean_offset_m", "sigma_m", "duration_s"} <= set(ev)
    f = res.fixes
    assert (f.loc[f["t"] >= d.t, "decided_track"] == track).all()
    assert f.loc[f["t"] < d.t, "decided_track"].isna().all()


def _statistics(sigma: float, cfg: GpsConfig, seeds: range, tau: float = 60.0) -> tuple[int, int, list[float]]:
    wrong, decided, times = 0, 0, []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        track = "D" if seed % 2 else "U"
        direction = 1 if (seed // 2) % 2 else -1
        km0 = 2000.0 + (seed % 7) * 1000.0
        gps, _, _ = fixes(rng, track=track, direction=direction, km0=km0, sigma=sigma, tau=tau)
        res = analyse_gps(gps, NET, cfg)
        wrong += any(d.track != track for d in res.decisions)
        if res.decisions and res.decisions[0].t <= 120.0:
            decided += 1
            times.append(res.decisions[0].t)
    return wrong, decided, times


def test_never_wrong_and_mostly_decided_within_120_s():
    """100 seeds, both tracks and directions, AR(1) σ 0.75 m per axis (≈ 1.06 m horizontal
    RMS), τ 60 s, 0.2 m white noise, the error model set to match: 0 wrong, ≥ 95 % decided
    within 120 s (measured: 98 %, median 15 s)."""
    wrong, decided, times = _statistics(0.75, model(0.75), range(100))
    assert wrong == 0
    assert decided >= 95
    assert np.median(times) <= 30.0


@pytest.mark.parametrize("tau", [60.0, 180.0])
def test_never_wrong_with_noisy_gps_when_the_model_says_so(tau):
    """σ 1.5 m per axis (the brief's τ 60 s, the simulator's τ 180 s) with the error model
    set to that receiver (σ 1.5 m, τ 180 s): 120 s hold ~1.2–1.8 independent samples of the
    lateral error, so the evidence is mostly weak — undecided, never wrong (measured over
    500 seeds: 5 % / 11 % decided within 120 s, 0 wrong). The model must describe the
    receiver: with the default model (σ 0.75 m) such a receiver gets ~4 % wrong decisions,
    which is why the README says to set ``gps.noise_sigma_m`` from the receiver's error."""
    cfg = replace(CFG, noise_sigma_m=1.5, noise_tau_s=180.0)
    wrong, _, _ = _statistics(1.5, cfg, range(100, 150), tau=tau)
    assert wrong == 0


def test_default_model_on_its_design_noise():
    """The default model (σ 0.75 m, τ 180 s) on that noise: never wrong, mostly decided
    within 120 s (measured over 200 seeds: 0 wrong, 93.5 %, median 15 s)."""
    wrong, decided, _ = _statistics(0.75, CFG, range(300, 360), tau=180.0)
    assert wrong == 0
    assert decided >= 50


def test_undecided_between_tracks_or_beside_them():
    for lateral in (-1.9, 3.8):  # midway between D and U; a track 3.8 m left of D, not in the GIS
        gps, _, _ = fixes(np.random.default_rng(1), sigma=0.3, lateral=lateral, seconds=200)
        assert analyse_gps(gps, NET, model(0.3)).decisions == []


# ------------------------------------------------------------------------ multipath, outages


def test_multipath_bursts_are_untrusted_and_do_not_mislead():
    cfg = model(0.75)
    for seed in range(10):
        bursts = ((40.0 + seed, 5.0, 15.0), (110.0, 3.0, 30.0), (170.0, 8.0, 10.0))
        gps, _, burst = fixes(np.random.default_rng(seed), track="U", bursts=bursts, seconds=220)
        res = analyse_gps(gps, NET, cfg)
        trusted = res.fixes["trusted"].to_numpy()
        assert not trusted[burst].any()
        t = res.fixes["t"].to_numpy()
        for t0, dur, _ in bursts:  # untrusted while a 30 s window holds the jump back
            assert not trusted[(t >= t0) & (t < t0 + dur + 29)].any()
        assert trusted[(t >= 5) & (t < 40)].all()
        assert all(d.track == "U" for d in res.decisions) and res.decisions


def test_outage_resets_windows():
    gps, _, _ = fixes(np.random.default_rng(2), outages=((50.0, 70.0),), seconds=120)
    f = analyse_gps(gps, NET, model(0.75)).fixes
    t = f["t"].to_numpy()
    out = (t >= 50) & (t < 70)
    assert not f["usable"][out].any() and not f["trusted"][out].any()
    assert f["rms_30"][out].isna().all()
    assert not f["trusted"][(t >= 70) & (t < 75)].any()  # 5 s of history first
    assert f["trusted"][(t >= 75)].all()
    assert f["rms_30"][t == 75].notna().all()


def test_off_rail_fixes_are_no_evidence():
    gps, _, _ = fixes(np.random.default_rng(3), sigma=0.3)
    n = 1500
    c = Cycles(
        np.arange(n) * 0.1,
        np.zeros(n),
        np.zeros(n),
        np.zeros(n),
        {},
        np.ones(n, dtype=np.int8),
        np.zeros(n, dtype=np.int8),  # PTO off: a road-rail vehicle on the road
        False,
        False,
    )
    cfg = model(0.3)
    assert analyse_gps(gps, NET, cfg, c).decisions == []
    assert len(analyse_gps(gps, NET, cfg).decisions) == 1


# ------------------------------------------------------------------------ crossover


@pytest.mark.parametrize("speed", [3.0, 10.0, 25.0])
def test_crossover_from_d_to_u(speed):
    cfg = model(0.75)
    for seed in range(5):
        gps, km, _ = fixes(
            np.random.default_rng(seed), sigma=0.75, speed=speed, seconds=300, crossover=(120.0, 60.0, "U")
        )
        res = analyse_gps(gps, NET, cfg)
        assert [d.track for d in res.decisions] == ["D", "U"], seed
        assert len(res.crossovers) == 1
        ev = res.crossovers[0]
        t_end = 120.0 + 60.0 / speed
        assert ev.type == "crossover" and 120.0 < ev.t <= t_end + 20.0
        assert ev.detail["from"] == "D" and ev.detail["to"] == "U" and ev.detail["rms_m"] >= cfg.crossover_rms_m
        assert ev.km_m == pytest.approx(km[int(ev.t)], abs=10.0)
        assert res.decisions[1].t > ev.t


# ------------------------------------------------- slow error through curves, bursts, windows


def test_constant_plane_error_turning_in_a_curve_is_no_crossover():
    """A 3.6 m error along the track before the 46° curve at km 10.8–11.4 turns into a
    lateral error of ~2.6 m inside it, toward U for one sign (the fixes' nearest track
    becomes U): no crossover, no change of decision."""
    cfg = replace(model(0.75), noise_tau_s=180.0)
    toward_u = 0
    for sign in (1.0, -1.0):
        gps, _, _ = fixes(np.random.default_rng(3), sigma=0.0, km0=10300.0, seconds=70, bias_along_m=3.6 * sign)
        res = analyse_gps(gps, NET, cfg)
        toward_u += int((res.fixes["track"] == "U").sum() >= 5)
        assert res.crossovers == [], sign
        assert [d.track for d in res.decisions] == ["D"], sign
    assert toward_u == 1  # the case the test is about did happen


@pytest.mark.parametrize("bias", [0.0, -3.6])
@pytest.mark.parametrize("t_cross", [30.0, 52.0])
def test_crossover_inside_a_curve_is_still_found(bias, t_cross):
    """The same curve with a real crossover (60 m long) just before or well inside it."""
    cfg = replace(model(0.75), noise_tau_s=180.0)
    gps, _, _ = fixes(
        np.random.default_rng(3), sigma=0.0, km0=10300.0, seconds=70, bias_along_m=bias, crossover=(t_cross, 60.0, "U")
    )
    res = analyse_gps(gps, NET, cfg)
    assert [c.detail["to"] for c in res.crossovers] == ["U"]
    assert t_cross < res.crossovers[0].t <= t_cross + 8.0
    assert [d.track for d in res.decisions] == ["D", "U"]


def test_fixes_after_a_smoothly_ramping_burst_are_not_trusted():
    """A 5 m burst over 8 s ramping on as sin^0.5 (the simulator's shape): after its first
    jump (3.1 m) the second differences stay below every threshold, so only the jump hold
    keeps the burst's fixes out."""
    gps, _, _ = fixes(np.random.default_rng(1), sigma=0.0, white=0.1, seconds=120, km0=3000.0)
    t = gps["t"].to_numpy()
    x, y = P.to_xy(gps["lon"].to_numpy(), gps["lat"].to_numpy())
    shape = np.where((t >= 60) & (t <= 68), np.sin(np.pi * np.clip((t - 60) / 8.0, 0, 1)) ** 0.5, 0.0)
    x = x + 5.0 * shape
    lon, lat = P.to_lonlat(x, y)
    gps = gps.assign(lat=lat, lon=lon)
    usable = np.ones(t.size, dtype=bool)
    trusted, _ = trust_filter(t, x, y, usable, CFG)
    assert trusted[50:61].all()
    assert not trusted[61 : 61 + int(CFG.jump_hold_s)].any()
    assert trusted[70 + int(CFG.jump_hold_s) :].all()
    loose, _ = trust_filter(t, x, y, usable, replace(CFG, jump_hold_s=0.0))
    assert loose[62:69].all()  # what the hold is for: fixes 3–5 m off, trusted without it


def test_recent_fixes_decide_when_older_ones_were_between_the_tracks():
    """50 s between the tracks (a slow error of 1.9 m toward U), then clearly on D: the 30 s
    window decides once the ambiguous fixes have left it (~27 s later); the 120 s window alone
    would wait ~110 s."""
    cfg = replace(model(0.75), noise_tau_s=180.0)
    gps, _, _ = fixes(np.random.default_rng(2), sigma=0.0, white=0.2, seconds=200, km0=3000.0)
    t = gps["t"].to_numpy()
    x, y = P.to_xy(gps["lon"].to_numpy(), gps["lat"].to_numpy())
    h = A.heading(A.chainage(3000.0 + 20.0 * t))
    lateral = np.where(t < 50, -1.9, 0.0)
    lon, lat = P.to_lonlat(x - lateral * np.sin(h), y + lateral * np.cos(h))
    gps = gps.assign(lat=lat, lon=lon)
    res = analyse_gps(gps, NET, cfg)
    assert [d.track for d in res.decisions] == ["D"]
    assert 60.0 <= res.decisions[0].t <= 82.0
    full_only = analyse_gps(gps, NET, replace(cfg, decide_recent_s=0.0))
    assert all(d.track == "D" for d in full_only.decisions)
    assert not full_only.decisions or full_only.decisions[0].t > 100.0
