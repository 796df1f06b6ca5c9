"""GPS unit: usable fixes, trust filter, map-matching, up/down decisions and crossovers
[S001 §4.2, §7; SPEC §5.4]. Everything per fix is vectorised; only the few moments where
the decision state changes are visited one by one.

**Usable fixes.** fix ≥ ``min_fix`` (D-GPS), HDOP ≤ ``max_hdop`` (missing HDOP is no
reason to drop a fix), finite lat/lon, a time stamp later than the previous fix's. Every
usable fix is map-matched (:mod:`dbtools.gis.matching`) to *all* tracks within
``max_offset_m``: km on the nearest segment of each track and the signed offset (positive
left of increasing km).

**Trust filter** [S001 §4.2.2: RMS of the second-to-second change over 5, 15, 30 s]. For
a moving train the per-second displacement p_k − p_{k−1} is ~20–30 m, so it is its
*change* that reveals a bad receiver state::

    a_k = (p_k − p_{k−1})/Δt_k − (p_{k−1} − p_{k−2})/Δt_{k−1}      [m, at 1 Hz; 2-D]
    RMS_w(k) = sqrt( mean_W |a_j|² − |mean_W a_j|² ),   W = {j : t_k − w < t_j ≤ t_k}

i.e. the scatter of the 2-D second difference of positions about its window mean (the
window mean is the smooth expectation: constant acceleration or braking cancels). A
time-correlated D-GPS error (Gauss-Markov, σ 1.5 m, τ ≥ 60 s) contributes ≤ 0.26·σ per
axis, white noise σ_w contributes √6·σ_w per axis: ≈ 1.0 m RMS in 2-D for σ_w = 0.25 m. A multipath
jump of J metres puts two values ±J into every window containing it: RMS ≳ J·sqrt(2/n) —
for J = 5 m, 3.3 / 2.1 / 1.65 m in the 5 / 15 / 30 s windows. A fix is **trusted** only
if, in every window ending at it, RMS_w ≤ ``rms_threshold_m[w]`` (defaults 2.5 / 1.8 /
1.5 m), its own |a_k| ≤ ``max_change_m`` (3 m: the first fix of a jump, seen only once by a
causal window), no fix of the last ``jump_hold_s`` (30 s) had a larger |a_k| (multipath
bursts ramp on and off smoothly, so the fixes after the first jump of a 5–8 m burst stay
below every window's threshold) and at least ``min_history_s`` of uninterrupted usable
fixes precede it. A
gap (no usable fix for more than ``max_gap_s``: outage, fix 1, high HDOP) resets all
windows. So a burst and the 30 s after it are untrusted; an isolated fix never is.

**Up/down decision.** At each trusted, matched fix k, the evidence is the trusted fixes of
the last ``decide_window_s`` (and after the last crossover). For each candidate track j:
n_j fixes matched, mean offset m_j, share_j of fixes whose nearest track is j. The slow
GPS error makes consecutive fixes dependent, so the standard error of m_j follows the
Gauss-Markov model (ρ = exp(−1 s/τ), ``noise_*``)::

    SE_j² = σ²·g(n_j) + σ_w²/n_j,   g(n) = [n(1+ρ)/(1−ρ) − 2ρ(1−ρⁿ)/(1−ρ)²] / n²

(1/g(n) is the effective sample size: 120 fixes are worth ~1.8 independent ones at
τ = 60 s, ~1.2 at τ = 180 s), inflated by the ratio of the window's own scatter to the model's
expectation when the data are noisier than the model. Under "on track j" m_j ~ N(0, SE²);
under "on track b" m_j ~ N(c, SE²) with c the offset of b's centreline, i.e. m_b ~ N(0, SE²).
The log-likelihood ratio is therefore ``LLR_jb = (m_b² − m_j²) / (2·SE_j²)``. Track j is
decided when n ≥ ``decide_min_fixes`` over ≥ ``decide_min_duration_s``, share_j ≥
``decide_min_share``, the track fits (|m_j| ≤ ``decide_fit_z``·SE_j and ≤
``decide_max_mean_m``: not between two tracks, not beside one) and LLR_jb ≥ ln(1/``decide_error``)
against every other candidate b (as in Wald's sequential test, the chance of ever deciding
the wrong track is then of the order of ``decide_error``). The test is re-evaluated at
every trusted fix ("as soon as the evidence suffices"), on the ``decide_window_s`` window and
on the last ``decide_recent_s`` (30 s) alone — older fixes that a slow error put between the
tracks must not hold back what the recent ones show; weak evidence leaves the run
*undecided* rather than wrong.
A :class:`TrackDecision` carries the km of the last fix on the decided track and
km_dir = sign of the km change over the evidence window (0 if below ``km_dir_min_m``).
After a decision nothing is emitted while the evidence agrees; another track is emitted
only when it passes the test with ``redecide_factor`` × the LLR threshold — or the normal
threshold after a detected crossover, when the next decision is always emitted (even for
the same track, which tells the solver the crossover was not one).

**Crossover** [S001 §7.1(b)]. With a decided base track d, at each trusted fix: RMS of the
offsets from d over the last ``crossover_window_s`` ≥ ``crossover_rms_m``; their mean
moved toward the other track of the line — relative to a ``crossover_ref_s`` reference
window ending ``crossover_lag_s`` before — by ≥ ``crossover_min_shift`` × the track
spacing and by ≥ ``crossover_z`` × the model's 1-σ drift of the slow error over that lag;
and past the midpoint between the tracks; and not explained by the slow error turning in a
curve: that error is nearly constant in the plane, so through a curve its along-track part
becomes lateral (3.6 m along the track before a 46° curve is 2.6 m across it inside). A
plane bias b (prior N(0, σ²) per axis) is fitted to the offsets r = b·N of the reference
window and the lag (N the track's left normal at each fix) and the RMS window's mean must
differ from b̂·N̄ by ≥ half the spacing and ≥ ``crossover_z`` × the prediction's 1-σ. On
straight track b̂·N̄ is the earlier mean; in a curve a crossover made while such an error
turns the other way can be missed — the redecision then finds the new track, never a
wrong one → ``Event(t, "crossover", km, {line_code, from, to, rms_m, shift_m})``. The
decision evidence restarts after it.

If ``cycles`` are given, fixes while the PTO says off-rail (road-rail vehicles on the road)
are matched and reported but are no evidence for decisions or crossovers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.matching import TrackIndex, track_index_for
from dbtools.network import Network
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.types import Event, FloatArray, GpsAnalysis, TrackDecision

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Fixed columns of ``GpsAnalysis.fixes``; one ``rms_<w>`` column per trust window follows
#: ``offset_m`` and the decided-track columns come last.
FIX_COLUMNS = ("t", "lat", "lon", "fix", "usable", "trusted", "line_code", "track", "km_m", "offset_m")
DECIDED_COLUMNS = ("decided_line_code", "decided_track", "decided_km_m", "decided_offset_m")
#: Evidence rows examined per vectorised step of the decision state machine.
_CHUNK = 2048


def analyse_gps(
    gps: pd.DataFrame | None,
    network: Network,
    cfg: GpsConfig,
    cycles: Cycles | None = None,
    *,
    index: TrackIndex | None = None,
) -> GpsAnalysis:
    """Trust, map-matching, up/down decisions and crossovers of one run's GPS stream.

    ``fixes`` has one row per GPS row (sorted by t): ``t, lat, lon, fix, usable, trusted,
    line_code, track, km_m, offset_m`` (nearest track), ``rms_<w>`` per trust window and
    ``decided_line_code, decided_track, decided_km_m, decided_offset_m`` (the decision in
    force and the fix's km/offset on that track). A missing stream gives an empty analysis.
    """
    if gps is None or not len(gps):
        return GpsAnalysis(_empty_fixes(cfg))
    if index is None:
        index = track_index_for(network)
    df = gps.sort_values("t", kind="stable").reset_index(drop=True)
    n = len(df)
    t = _col(df, "t")
    lat, lon = _col(df, "lat"), _col(df, "lon")
    fixq = np.nan_to_num(_col(df, "fix"), nan=0.0)
    hdop = _col(df, "hdop")
    usable = np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon) & (fixq >= cfg.min_fix) & ~(hdop > cfg.max_hdop)
    usable[1:] &= t[1:] > t[:-1]
    x, y = index.to_xy(np.where(usable, lat, np.nan), np.where(usable, lon, np.nan))
    x = np.where(usable, x, np.nan)
    y = np.where(usable, y, np.nan)

    trusted, rms = trust_filter(t, x, y, usable, cfg)
    matches = index.match_xy(x, y, max_offset_m=cfg.max_offset_m)
    best = matches[matches["best"].to_numpy()]
    bf = best["fix"].to_numpy()
    line_code = np.full(n, None, dtype=object)
    track = np.full(n, None, dtype=object)
    km = np.full(n, np.nan)
    off = np.full(n, np.nan)
    line_code[bf] = best["line_code"].astype(str).to_numpy()
    track[bf] = best["track"].astype(str).to_numpy()
    km[bf] = best["km_m"].to_numpy()
    off[bf] = best["offset_m"].to_numpy()

    on_rail = np.ones(n, dtype=bool)
    if cycles is not None and cycles.n:
        i = np.clip(np.searchsorted(cycles.t, t, side="right") - 1, 0, cycles.n - 1)
        on_rail = cycles.pto[i] == 1
    evidence = trusted & on_rail & np.isin(np.arange(n), bf)
    ev = _Evidence.build(t, evidence, matches, index)
    decisions, crossovers, periods = _decide(ev, index, cfg)

    out = pd.DataFrame(
        {
            "t": t,
            "lat": lat,
            "lon": lon,
            "fix": fixq.astype(np.int64),
            "usable": usable,
            "trusted": trusted,
            "line_code": pd.array(line_code, dtype="string"),
            "track": pd.array(track, dtype="string"),
            "km_m": km,
            "offset_m": off,
        }
    )
    for w, r in rms.items():
        out[f"rms_{w}"] = r
    _decided_columns(out, periods, matches, index)
    return GpsAnalysis(out, decisions, crossovers)


@dataclass(frozen=True)
class TrackOdds:
    """Evidence for one candidate track over a window (see :func:`track_odds`)."""

    line_code: str
    track: str
    n_fixes: int
    mean_offset_m: float
    sigma_m: float
    llr: float
    """min over the other candidates b of (m_b² − m_j²)/(2 SE_j²): > 0 = this track is the
    likeliest; ≥ ln(1/``decide_error``) would decide it."""


def track_odds(
    fixes: pd.DataFrame, network: Network | TrackIndex, cfg: GpsConfig, t_from: float, t_to: float
) -> list[TrackOdds]:
    """The up/down test's statistics over the trusted fixes in (t_from, t_to] of ``fixes``
    (an :func:`analyse_gps` table), per candidate track, likeliest first — where the
    evidence leans when it does not (yet) decide. Empty without trusted matched fixes."""
    if not len(fixes):
        return []
    t = _col(fixes, "t")
    sel = (t > t_from) & (t <= t_to) & fixes["trusted"].fillna(False).to_numpy(dtype=bool)
    if not sel.any():
        return []
    index = network if isinstance(network, TrackIndex) else track_index_for(network)
    ts = t[sel]
    x, y = index.to_xy(_col(fixes, "lat")[sel], _col(fixes, "lon")[sel])
    matches = index.match_xy(x, y, max_offset_m=cfg.max_offset_m)
    if not len(matches):
        return []
    ev = _Evidence.build(ts, np.isin(np.arange(ts.size), matches["fix"].to_numpy()), matches, index)
    if ev.size == 0:
        return []
    w = _windows(ev, np.array([ev.size - 1]), 0, cfg, float(t_to - t_from))
    out = [
        TrackOdds(
            index.keys[int(tid)][0],
            index.keys[int(tid)][1],
            int(w.n[0, j]),
            float(w.mean[0, j]),
            float(np.sqrt(w.se2[0, j])),
            float(w.llr[0, j]),
        )
        for j, tid in enumerate(ev.tracks)
        if w.n[0, j] > 0
    ]
    return sorted(out, key=lambda o: -o.llr)


def _col(df: pd.DataFrame, name: str) -> FloatArray:
    if name not in df.columns:
        return np.full(len(df), np.nan)
    return pd.to_numeric(df[name], errors="coerce").to_numpy(dtype=float, na_value=np.nan)


def _empty_fixes(cfg: GpsConfig) -> pd.DataFrame:
    cols: dict[str, pd.Series] = {c: pd.Series([], dtype=float) for c in FIX_COLUMNS}
    cols["fix"] = pd.Series([], dtype=np.int64)
    cols["usable"] = pd.Series([], dtype=bool)
    cols["trusted"] = pd.Series([], dtype=bool)
    for c in ("line_code", "track"):
        cols[c] = pd.Series([], dtype="string")
    for w in cfg.windows_s:
        cols[f"rms_{w}"] = pd.Series([], dtype=float)
    for c in DECIDED_COLUMNS:
        cols[c] = pd.Series([], dtype="string" if c in ("decided_line_code", "decided_track") else float)
    return pd.DataFrame(cols)


# ---------------------------------------------------------------------------------- trust


def trust_filter(
    t: FloatArray, x: FloatArray, y: FloatArray, usable: BoolArray, cfg: GpsConfig
) -> tuple[BoolArray, dict[int, FloatArray]]:
    """(trusted, {window: RMS}) per fix — the statistic of the module docstring.

    Runs of usable fixes are cut where a fix is unusable or the time step exceeds
    ``max_gap_s``; second differences and windows never reach across a cut.
    """
    n = t.size
    rms = {int(w): np.full(n, np.nan) for w in cfg.windows_s}
    trusted = np.zeros(n, dtype=bool)
    u = np.flatnonzero(usable)
    if u.size == 0:
        return trusted, rms
    tu, xu, yu = t[u], x[u], y[u]
    new = np.ones(u.size, dtype=bool)
    new[1:] = (np.diff(tu) > cfg.max_gap_s) | (np.diff(u) > 1)
    starts = np.flatnonzero(new)
    first = starts[np.cumsum(new) - 1]
    pos = np.arange(u.size)
    valid = pos - first >= 2
    ax = np.zeros(u.size)
    ay = np.zeros(u.size)
    if u.size > 2:
        dt = np.diff(tu)
        vx, vy = np.diff(xu) / dt, np.diff(yu) / dt
        ax[2:] = vx[1:] - vx[:-1]
        ay[2:] = vy[1:] - vy[:-1]
    ax[~valid] = 0.0
    ay[~valid] = 0.0
    cn = np.concatenate([[0], np.cumsum(valid)])
    cx = np.concatenate([[0.0], np.cumsum(ax)])
    cy = np.concatenate([[0.0], np.cumsum(ay)])
    cq = np.concatenate([[0.0], np.cumsum(ax * ax + ay * ay)])
    jump = valid & (np.hypot(ax, ay) > cfg.max_change_m)
    last_jump = np.maximum.accumulate(np.where(jump, tu, -np.inf))
    ok = (tu - tu[first] >= cfg.min_history_s - 1e-9) & valid & ~jump
    # a burst may ramp on smoothly after its first jump, below every window's threshold
    ok &= ~(tu - last_jump < cfg.jump_hold_s)
    for w, thr in zip(cfg.windows_s, cfg.rms_threshold_m, strict=True):
        lo = np.maximum(np.searchsorted(tu, tu - w, side="right"), first + 2)
        hi = pos + 1
        cnt = np.where(hi > lo, cn[hi] - cn[np.minimum(lo, hi)], 0)
        lo_c = np.minimum(lo, hi)
        with np.errstate(invalid="ignore", divide="ignore"):
            mx = (cx[hi] - cx[lo_c]) / cnt
            my = (cy[hi] - cy[lo_c]) / cnt
            var = (cq[hi] - cq[lo_c]) / cnt - mx * mx - my * my
        r = np.where(cnt >= 2, np.sqrt(np.maximum(var, 0.0)), np.nan)
        rms[int(w)][u] = r
        ok &= r <= thr
    trusted[u] = ok
    return trusted, rms


# ------------------------------------------------------------------------------ evidence


@dataclass
class _Evidence:
    """Trusted, matched fixes (rows e) × candidate tracks (columns j), with prefix sums."""

    fix: IntArray
    """Row in the fixes table of each evidence row."""
    t: FloatArray
    tracks: IntArray
    """Track id (TrackIndex.keys) of each column."""
    r: FloatArray
    """(E, J) offsets, NaN where the track is not a candidate."""
    km: FloatArray
    near: IntArray
    """Column of each row's nearest track."""
    cn: FloatArray
    cs: FloatArray
    cq: FloatArray
    cnear: FloatArray
    s_ne: FloatArray
    """Prefix sums of the left normal (east, north components) of each candidate track at the
    fix, and of the products the crossover's rotating-bias fit needs (see :func:`_crossing`)."""
    s_nn: FloatArray
    s_ee: FloatArray
    s_en: FloatArray
    s_nn2: FloatArray
    s_re: FloatArray
    s_rn: FloatArray

    @classmethod
    def build(cls, t: FloatArray, evidence: BoolArray, matches: pd.DataFrame, index: TrackIndex) -> _Evidence:
        rows = np.flatnonzero(evidence)
        m = matches[evidence[matches["fix"].to_numpy()]] if len(matches) else matches
        tracks = np.unique(m["track_id"].to_numpy()) if len(m) else np.zeros(0, dtype=np.int64)
        e_of = np.full(t.size, -1, dtype=np.int64)
        e_of[rows] = np.arange(rows.size)
        r = np.full((rows.size, tracks.size), np.nan)
        km = np.full((rows.size, tracks.size), np.nan)
        near = np.zeros(rows.size, dtype=np.int64)
        ne = np.zeros((rows.size, tracks.size))
        nn = np.zeros((rows.size, tracks.size))
        if len(m):
            e = e_of[m["fix"].to_numpy()]
            j = np.searchsorted(tracks, m["track_id"].to_numpy())
            r[e, j] = m["offset_m"].to_numpy()
            km[e, j] = m["km_m"].to_numpy()
            b = m["best"].to_numpy()
            near[e[b]] = j[b]
            # left normal of increasing km = heading turned +90°: offsets are positive to the left
            ne[e, j] = -m["dir_n"].to_numpy()
            nn[e, j] = m["dir_e"].to_numpy()
        has = np.isfinite(r)
        zero = np.zeros((1, tracks.size))
        onehot = (near[:, None] == np.arange(tracks.size)[None, :]).astype(float)
        r0 = np.where(has, r, 0.0)

        def csum(a: FloatArray) -> FloatArray:
            return np.concatenate([zero, np.cumsum(a, axis=0)])

        return cls(
            rows,
            t[rows],
            tracks,
            r,
            km,
            near,
            csum(has),
            csum(r0),
            csum(r0 * r0),
            csum(onehot),
            csum(ne),
            csum(nn),
            csum(ne * ne),
            csum(ne * nn),
            csum(nn * nn),
            csum(r0 * ne),
            csum(r0 * nn),
        )

    @property
    def size(self) -> int:
        return int(self.t.size)


def mean_variance_factor(n: npt.ArrayLike, rho: float) -> FloatArray:
    """g(n): variance of the mean of n consecutive unit-variance AR(1) samples (lag-1
    correlation ρ); 1/g(n) is the effective sample size."""
    na = np.maximum(np.asarray(n, dtype=float), 1.0)
    if rho <= 0.0:
        return 1.0 / na
    return (na * (1 + rho) / (1 - rho) - 2 * rho * (1 - rho**na) / (1 - rho) ** 2) / (na * na)


@dataclass
class _Window:
    """Decision statistics of the windows ending at evidence rows ``i`` (vectorised)."""

    i: IntArray
    lo: IntArray
    n: FloatArray
    """(rows, J) fixes matched per track."""
    mean: FloatArray
    share: FloatArray
    se2: FloatArray
    llr: FloatArray
    """(rows, J) min over the other candidates of (m_b² − m_j²)/(2 SE_j²)."""
    ok: BoolArray
    """(rows, J) all conditions except the LLR threshold."""


def _windows(ev: _Evidence, i: IntArray, reset_lo: int, cfg: GpsConfig, length_s: float) -> _Window:
    lo = np.maximum(np.searchsorted(ev.t, ev.t[i] - length_s, side="right"), reset_lo)
    hi = i + 1
    total = (hi - lo).astype(float)[:, None]
    n = ev.cn[hi] - ev.cn[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (ev.cs[hi] - ev.cs[lo]) / n
        msq = (ev.cq[hi] - ev.cq[lo]) / n
        share = (ev.cnear[hi] - ev.cnear[lo]) / total
    rho = float(np.exp(-1.0 / cfg.noise_tau_s)) if cfg.noise_tau_s > 0 else 0.0
    g = mean_variance_factor(n, rho)
    sig2, w2 = cfg.noise_sigma_m**2, cfg.noise_white_m**2
    nn = np.maximum(n, 1.0)
    se2 = sig2 * g + w2 / nn
    expected_scatter = sig2 * (1.0 - g) + w2 * (1.0 - 1.0 / nn)
    with np.errstate(invalid="ignore", divide="ignore"):
        inflate = np.where(n >= 5, np.maximum(1.0, (msq - mean * mean) / expected_scatter), 1.0)
    se2 = se2 * np.nan_to_num(inflate, nan=1.0, posinf=1e9)
    m2 = np.where(n > 0, mean * mean, np.inf)
    llr = np.full(n.shape, np.inf)
    for j in range(n.shape[1]):
        others = np.delete(m2, j, axis=1)
        if others.shape[1]:
            llr[:, j] = (others.min(axis=1) - m2[:, j]) / (2.0 * se2[:, j])
    duration = ev.t[i] - ev.t[np.minimum(lo, i)]
    ok = (
        (n >= cfg.decide_min_fixes)
        & (duration >= cfg.decide_min_duration_s - 1e-9)[:, None]
        & (share >= cfg.decide_min_share)
        & (np.abs(mean) <= np.minimum(cfg.decide_max_mean_m, cfg.decide_fit_z * np.sqrt(se2)))
    )
    return _Window(i, lo, n, mean, share, se2, llr, ok)


def _merge_windows(w: _Window, wr: _Window, use_r: BoolArray) -> _Window:
    """Per (row, track), the recent window's statistics where ``use_r``, else the full one's."""
    row_r = use_r.any(axis=1)
    return _Window(
        w.i,
        np.where(row_r, wr.lo, w.lo),
        np.where(use_r, wr.n, w.n),
        np.where(use_r, wr.mean, w.mean),
        np.where(use_r, wr.share, w.share),
        np.where(use_r, wr.se2, w.se2),
        np.where(use_r, wr.llr, w.llr),
        np.where(use_r, wr.ok, w.ok),
    )


def _crossing(ev: _Evidence, i: IntArray, reset_lo: int, d: int, o: int, cfg: GpsConfig) -> tuple[BoolArray, ...]:
    """Crossover condition from base column d toward column o at rows i (vectorised)."""
    lo = np.maximum(np.searchsorted(ev.t, ev.t[i] - cfg.crossover_window_s, side="right"), reset_lo)
    t_ref_end = ev.t[i] - cfg.crossover_window_s - cfg.crossover_lag_s
    le = np.minimum(np.maximum(np.searchsorted(ev.t, t_ref_end, side="right"), reset_lo), lo)
    lr = np.minimum(np.maximum(np.searchsorted(ev.t, t_ref_end - cfg.crossover_ref_s, side="right"), reset_lo), le)
    hi = i + 1
    n5 = ev.cn[hi, d] - ev.cn[lo, d]
    nref = ev.cn[le, d] - ev.cn[lr, d]
    both = np.isfinite(ev.r[:, d]) & np.isfinite(ev.r[:, o])
    cc = np.concatenate([[0.0], np.cumsum(np.where(both, ev.r[:, d] - ev.r[:, o], 0.0))])
    cb = np.concatenate([[0], np.cumsum(both)])
    with np.errstate(invalid="ignore", divide="ignore"):
        rms5 = np.sqrt((ev.cq[hi, d] - ev.cq[lo, d]) / n5)
        m5 = (ev.cs[hi, d] - ev.cs[lo, d]) / n5
        mref = (ev.cs[le, d] - ev.cs[lr, d]) / nref
        spacing = (cc[hi] - cc[lr]) / (cb[hi] - cb[lr])
    side = np.sign(spacing)
    shift = (m5 - mref) * side
    # what the slow error alone moves between the two window centres (model, 1-σ)
    lag = 0.5 * cfg.crossover_window_s + cfg.crossover_lag_s + 0.5 * cfg.crossover_ref_s
    drift = cfg.noise_sigma_m * np.sqrt(2.0 * (1.0 - np.exp(-lag / cfg.noise_tau_s))) if cfg.noise_tau_s > 0 else 0.0
    # the slow error is (nearly) constant in the plane, not across the track: through a curve
    # it turns from along-track into lateral. Fit that bias b (2-D, prior N(0, σ²)) to the
    # offsets r = b·N of the reference window and the lag (N: the track's left normal) and ask
    # how far the RMS window's mean lies from what b alone predicts there.
    unexplained, sd_pred = _rotating_bias_residual(ev, d, lr, lo, hi, n5, m5, drift, cfg)
    cross = (
        (n5 >= 3)
        & (nref >= 3)
        & (rms5 >= cfg.crossover_rms_m)
        & (shift >= np.maximum(cfg.crossover_min_shift * np.abs(spacing), cfg.crossover_z * drift))
        & (unexplained * side >= np.maximum(0.5 * np.abs(spacing), cfg.crossover_z * sd_pred))
        & (m5 * side >= 0.5 * np.abs(spacing))
        & np.isfinite(spacing)
    )
    return cross, rms5, shift


def _rotating_bias_residual(
    ev: _Evidence,
    d: int,
    lr: IntArray,
    lo: IntArray,
    hi: IntArray,
    n5: FloatArray,
    m5: FloatArray,
    drift: float,
    cfg: GpsConfig,
) -> tuple[FloatArray, FloatArray]:
    """(m5 − b̂·N̄5, 1-σ of that prediction incl. the drift) per row (vectorised 2×2 solves);
    n5, m5: count and mean offset of the RMS window [lo, hi).

    b̂ is the MAP estimate of a constant plane bias from the offsets of rows [lr, lo) on
    column d (per-fix σ² = white² + drift², prior σ = ``noise_sigma_m`` per axis); N̄5 is the
    mean left normal over the RMS window [lo, hi). On straight track only b's lateral part is
    observable and b̂·N̄5 is the reference mean; through a curve the along-track part is seen too.
    """
    s_w2 = cfg.noise_white_m**2 + drift**2
    p = 1.0 / max(cfg.noise_sigma_m**2, 1e-12)
    a11 = (ev.s_ee[lo, d] - ev.s_ee[lr, d]) / s_w2 + p
    a12 = (ev.s_en[lo, d] - ev.s_en[lr, d]) / s_w2
    a22 = (ev.s_nn2[lo, d] - ev.s_nn2[lr, d]) / s_w2 + p
    r1 = (ev.s_re[lo, d] - ev.s_re[lr, d]) / s_w2
    r2 = (ev.s_rn[lo, d] - ev.s_rn[lr, d]) / s_w2
    det = a11 * a22 - a12 * a12
    i11, i12, i22 = a22 / det, -a12 / det, a11 / det  # posterior covariance of b
    be, bn = i11 * r1 + i12 * r2, i12 * r1 + i22 * r2
    with np.errstate(invalid="ignore", divide="ignore"):
        ue = (ev.s_ne[hi, d] - ev.s_ne[lo, d]) / n5
        un = (ev.s_nn[hi, d] - ev.s_nn[lo, d]) / n5
    pred = be * ue + bn * un
    var = ue * ue * i11 + 2.0 * ue * un * i12 + un * un * i22
    return m5 - pred, np.sqrt(np.maximum(var, 0.0) + drift * drift)


def _decide(
    ev: _Evidence, index: TrackIndex, cfg: GpsConfig
) -> tuple[list[TrackDecision], list[Event], list[tuple[float, int]]]:
    """The decision state machine over the evidence rows (vectorised in chunks)."""
    decisions: list[TrackDecision] = []
    crossovers: list[Event] = []
    periods: list[tuple[float, int]] = []  # (t from, track id) of the decision in force
    if ev.size == 0 or ev.tracks.size == 0:
        return decisions, crossovers, periods
    thr = float(np.log(1.0 / cfg.decide_error))
    current: int | None = None  # column of the decided track
    pending = False  # a crossover was detected since the last decision
    reset_lo = 0
    pos = 0
    keys = index.keys
    while pos < ev.size:
        i = np.arange(pos, min(pos + _CHUNK, ev.size))
        need = thr if (current is None or pending) else thr * cfg.redecide_factor
        w = _windows(ev, i, reset_lo, cfg, cfg.decide_window_s)
        cand = w.ok & (w.llr >= need)
        if 0.0 < cfg.decide_recent_s < cfg.decide_window_s:
            # the recent fixes alone may decide when older ones were ambiguous
            wr = _windows(ev, i, reset_lo, cfg, cfg.decide_recent_s)
            cand_r = wr.ok & (wr.llr >= need)
            use_r = cand_r & ~cand
            w = _merge_windows(w, wr, use_r)
            cand = cand | cand_r
        if current is not None and not pending:
            cand[:, current] = False
        dec_rows = np.flatnonzero(cand.any(axis=1))
        first_dec = int(dec_rows[0]) if dec_rows.size else None
        first_cross = None
        other = None
        if current is not None and not pending:
            other = _partner(ev, current, keys)
            if other is not None:
                cross, rms5, shift = _crossing(ev, i, reset_lo, current, other, cfg)
                rows = np.flatnonzero(cross)
                first_cross = int(rows[0]) if rows.size else None
        if first_cross is not None and (first_dec is None or first_cross <= first_dec):
            assert current is not None and other is not None
            e = int(i[first_cross])
            d_id, o_id = int(ev.tracks[current]), int(ev.tracks[other])
            crossovers.append(
                Event(
                    float(ev.t[e]),
                    "crossover",
                    _finite(float(ev.km[e, current])),
                    detail={
                        "line_code": keys[d_id][0],
                        "from": keys[d_id][1],
                        "to": keys[o_id][1],
                        "rms_m": round(float(rms5[first_cross]), 3),
                        "shift_m": round(float(shift[first_cross]), 3),
                    },
                )
            )
            pending = True
            reset_lo = e + 1
            pos = e + 1
            continue
        if first_dec is not None:
            e = int(i[first_dec])
            j = int(np.argmax(np.where(cand[first_dec], w.llr[first_dec], -np.inf)))
            decisions.append(_decision(ev, w, first_dec, j, keys, cfg.km_dir_min_m))
            periods.append((float(ev.t[e]), int(ev.tracks[j])))
            current = j
            pending = False
            pos = e + 1
            continue
        pos = int(i[-1]) + 1
    return decisions, crossovers, periods


def _partner(ev: _Evidence, col: int, keys: list[tuple[str, str]]) -> int | None:
    """The other track of the same line with the most evidence (crossover target)."""
    line = keys[int(ev.tracks[col])][0]
    best, best_n = None, 0.0
    for j, tid in enumerate(ev.tracks):
        if j != col and keys[int(tid)][0] == line and ev.cn[-1, j] > best_n:
            best, best_n = j, float(ev.cn[-1, j])
    return best


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _decision(
    ev: _Evidence, w: _Window, row: int, j: int, keys: list[tuple[str, str]], km_dir_min_m: float
) -> TrackDecision:
    e, lo = int(w.i[row]), int(w.lo[row])
    seen = np.flatnonzero(np.isfinite(ev.km[lo : e + 1, j])) + lo
    km_first, km_last = float(ev.km[seen[0], j]), float(ev.km[seen[-1], j])
    dkm = km_last - km_first
    tid = int(ev.tracks[j])
    return TrackDecision(
        t=float(ev.t[e]),
        line_code=keys[tid][0],
        track=keys[tid][1],
        km_m=km_last,
        km_dir=int(np.sign(dkm)) if abs(dkm) >= km_dir_min_m else 0,
        evidence={
            "n_fixes": int(w.n[row, j]),
            "mean_offset_m": round(float(w.mean[row, j]), 3),
            "sigma_m": round(float(np.sqrt(w.se2[row, j])), 3),
            "duration_s": round(float(ev.t[e] - ev.t[lo]), 1),
            "share": round(float(w.share[row, j]), 3),
            "llr": round(float(w.llr[row, j]), 2) if np.isfinite(w.llr[row, j]) else None,
        },
    )


def _decided_columns(
    out: pd.DataFrame, periods: list[tuple[float, int]], matches: pd.DataFrame, index: TrackIndex
) -> None:
    n = len(out)
    tid = np.full(n, -1, dtype=np.int64)
    if periods:
        t_from = np.array([p[0] for p in periods])
        k = np.searchsorted(t_from, out["t"].to_numpy(dtype=float), side="right") - 1
        ids = np.array([p[1] for p in periods], dtype=np.int64)
        tid = np.where(k >= 0, ids[np.clip(k, 0, None)], -1)
    lc = np.full(n, None, dtype=object)
    tr = np.full(n, None, dtype=object)
    has = tid >= 0
    if has.any():
        lc[has] = [index.keys[i][0] for i in tid[has]]
        tr[has] = [index.keys[i][1] for i in tid[has]]
    km = np.full(n, np.nan)
    off = np.full(n, np.nan)
    if len(matches) and has.any():
        f = matches["fix"].to_numpy()
        sel = tid[f] == matches["track_id"].to_numpy()
        km[f[sel]] = matches["km_m"].to_numpy()[sel]
        off[f[sel]] = matches["offset_m"].to_numpy()[sel]
    out["decided_line_code"] = pd.array(lc, dtype="string")
    out["decided_track"] = pd.array(tr, dtype="string")
    out["decided_km_m"] = km
    out["decided_offset_m"] = off
