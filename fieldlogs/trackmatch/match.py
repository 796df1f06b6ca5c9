"""A GNSS-only trace matched to a network path as a whole (SPEC §8.3; Newson & Krumm 2009).

**Candidates** (:mod:`.candidates`): per fix the nearest segment of every track within
``radius_m`` (at most ``max_tracks``). A fix with none — hundreds of metres off, or no
position (a tunnel) — is skipped: the chain is re-linked across the gap, never forced.

**Emission** of candidate j of a fix: log e = −½·(d/σ)² − ½·(θ/σ_θ)², d the perpendicular
distance, σ the fix's horizontal 1-σ (``sigma_lat_m``/``sigma_lon_m``: their RMS, where the
stream has them; else ``sigma_m``); θ ∈ [0, 90°] the angle between the track and the fix's
heading — the chord from the previous to the next fix, where it is at least
``heading_min_move_m`` long (tp-lib's heading term; a track's direction of travel is not
known, so the angle is taken modulo 180°).

**Transition** between candidates i (fix a) and j (fix b, the next fix with candidates):
log a = −|r − g|/β − λ·[the tracks differ], g the plane distance between the two fixes (the
network's metric CRS: within 0.04 % of the great-circle distance in a UTM zone), r the
route distance between
the candidates' positions through the topology (:mod:`.routes`: the same track |Δs|; else
through whole tracks over navigable connections only), searched up to
``route_factor``·g + ``route_margin_m``: beyond it, or with no route, the transition is
impossible (−∞). λ = ``change_penalty`` (0.1) makes a change of track cost a little, so
that fixes at a track's end (the foot as near to either track) do not flicker between the
two tracks — the model has no direction of travel, and going back and forth by a metre
across a joint fits the noise as well as staying (on the hand-made crossover pair with 1–2 m
noise: 8 of 20 seeded traces flicker at λ = 0, none at 0.1; larger λ starts to bias against
networks cut into many short tracks).

**Decoding** (:mod:`.hmm`): Viterbi gives one candidate per fix, forward–backward the
posterior γ of every candidate. Where no transition is possible the chain breaks; a chain of
at most ``outlier_run`` fixes beside a longer one is taken for outliers (fixes near a track
they cannot be on), its fixes set aside, and the rest decoded again (up to
``MAX_PASSES`` times).

**Path**: the Viterbi tracks in time order, consecutive fixes on one track merged, the tracks
a route passes whole between two fixes inserted (so consecutive path tracks are connected
navigably); ``probability`` of a track with fixes = mean γ of its fixes' candidates on it, of
a passed track = the posterior ξ of the transition it lies on; ``t_from``/``t_to`` its
first/last fix (a passed track: the fixes before and after it); ``chain`` numbers the
chains (a new chain is not connected to the one before).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

from dbtools.gis.track_candidates import Candidates, find_candidates, segment_tree
from dbtools.gis.track_segments import TrackGeometry, build_geometry
from dbtools.network import Network
from fieldlogs.trackmatch.result import MATCHED, NO_CANDIDATE, NO_POSITION, OUTLIER, Hmm, TrackMatch
from fieldlogs.trackmatch.routes import Routes, route_distances

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
#: Decoding passes at most (each may set aside a short chain of outliers).
MAX_PASSES = 5


@dataclass(frozen=True)
class MatchSettings:
    """Parameters of the HMM (module docstring)."""

    radius_m: float = 50.0
    sigma_m: float = 10.0
    beta_m: float = 20.0
    heading_sigma_deg: float = 30.0
    heading_min_move_m: float = 5.0
    max_tracks: int = 8
    route_factor: float = 3.0
    route_margin_m: float = 200.0
    outlier_run: int = 10
    change_penalty: float = 0.1


@dataclass
class _Model:
    geo: TrackGeometry
    routes: Routes
    tree: object


def _model(net: Network) -> _Model:
    from dbtools.topology import topology

    def build() -> _Model:
        geo = build_geometry(net)
        return _Model(geo, Routes(topology(net), geo.index_of, geo.length_m), segment_tree(geo))

    return net.cached(("trackmatch", "model"), build)


def _headings(x: F64, y: F64, min_move: float) -> tuple[F64, F64]:
    """Unit heading per fix from its neighbours' chord (NaN where shorter than ``min_move``)."""
    hx, hy = np.full(len(x), np.nan), np.full(len(x), np.nan)
    if len(x) >= 2:
        xs, ys = np.r_[x[0], x, x[-1]], np.r_[y[0], y, y[-1]]
        cx, cy = xs[2:] - xs[:-2], ys[2:] - ys[:-2]
        n = np.hypot(cx, cy)
        ok = n >= min_move
        hx[ok], hy[ok] = cx[ok] / n[ok], cy[ok] / n[ok]
    return hx, hy


def _emissions(c: Candidates, fix_of: I64, sigma: F64, hx: F64, hy: F64, s: MatchSettings) -> F64:
    d = c.dist_m / sigma[fix_of]
    loge = -0.5 * d * d
    cos = np.abs(hx[fix_of] * c.ux + hy[fix_of] * c.uy)
    theta = np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), 0.0, 1.0))
    loge -= 0.5 * (theta / np.radians(s.heading_sigma_deg)) ** 2
    return loge


def _build(c: Candidates, steps: I64, loge_all: F64, x: F64, y: F64, model: _Model, s: MatchSettings) -> Hmm:
    counts = (c.offsets[steps + 1] - c.offsets[steps]).astype(np.int64)
    coff = np.r_[0, np.cumsum(counts)].astype(np.int64)
    cand = (np.repeat(c.offsets[steps] - coff[:-1], counts) + np.arange(coff[-1])).astype(np.int64)
    pairs = np.r_[0, counts[:-1] * counts[1:]] if len(steps) else np.empty(0, dtype=np.int64)
    poff = np.r_[0, np.cumsum(pairs)[:-1]].astype(np.int64) if len(steps) else np.empty(0, dtype=np.int64)
    total = int(pairs.sum()) if len(steps) else 0
    step = np.repeat(np.arange(len(steps)), pairs)
    q = np.arange(total) - np.repeat(poff, pairs)
    m = counts[step]
    i = cand[coff[step - 1] + q // m] if total else np.empty(0, dtype=np.int64)
    j = cand[coff[step] + q % m] if total else np.empty(0, dtype=np.int64)
    fa, fb = steps[step - 1], steps[step]
    g = np.hypot(x[fb] - x[fa], y[fb] - y[fa])
    route, ends = route_distances(
        model.routes, c.track[i], c.pos_m[i], c.track[j], c.pos_m[j], s.route_factor * g + s.route_margin_m
    )
    logt = -np.abs(route - g) / s.beta_m - s.change_penalty * (c.track[i] != c.track[j])
    return Hmm(steps, coff, cand, loge_all[cand], poff, logt, ends)


def _outliers(start: npt.NDArray[np.bool_], steps: I64, run: int) -> I64:
    """Fixes of the short chains to set aside (module docstring)."""
    first = np.flatnonzero(start)
    length = np.diff(np.r_[first, len(start)])
    if len(first) < 2 or length.max() <= run:
        return np.empty(0, dtype=np.int64)
    drop = [steps[a : a + n] for a, n in zip(first, length, strict=True) if n <= run]
    return np.concatenate(drop) if drop else np.empty(0, dtype=np.int64)


def match_trace(
    net: Network,
    t: F64,
    lat: F64,
    lon: F64,
    sigma_m: F64 | None = None,
    settings: MatchSettings | None = None,
) -> TrackMatch:
    """Match fixes (time [s], lat/lon [deg], optional 1-σ per fix [m]) to a path on ``net``."""
    from fieldlogs.trackmatch.hmm import decode
    from fieldlogs.trackmatch.path import assemble

    s = settings or MatchSettings()
    model = _model(net)
    t, lat, lon = (np.asarray(v, dtype=np.float64) for v in (t, lat, lon))
    has_pos = np.isfinite(lat) & np.isfinite(lon)
    x, y = np.full(len(t), np.nan), np.full(len(t), np.nan)
    if has_pos.any():
        x[has_pos], y[has_pos] = model.geo.projector.to_xy(lon[has_pos], lat[has_pos])
    sig = np.full(len(t), s.sigma_m) if sigma_m is None else np.asarray(sigma_m, dtype=np.float64)
    sig = np.where(np.isfinite(sig) & (sig > 0), sig, s.sigma_m)
    pos_idx = np.flatnonzero(has_pos)
    c = find_candidates(model.geo, model.tree, x[pos_idx], y[pos_idx], s.radius_m, s.max_tracks)
    fix_of = np.repeat(pos_idx, np.diff(c.offsets))
    offsets = np.zeros(len(t) + 1, dtype=np.int64)
    offsets[pos_idx + 1] = np.diff(c.offsets)
    c = Candidates(np.cumsum(offsets), c.track, c.dist_m, c.offset_m, c.pos_m, c.km_m, c.ux, c.uy)
    hx, hy = np.full(len(t), np.nan), np.full(len(t), np.nan)
    hx[pos_idx], hy[pos_idx] = _headings(x[pos_idx], y[pos_idx], s.heading_min_move_m)
    loge_all = _emissions(c, fix_of, sig, hx, hy, s)
    outlier = np.zeros(len(t), dtype=bool)
    with_cand = np.diff(c.offsets) > 0
    for n_pass in range(MAX_PASSES):
        steps = np.flatnonzero(with_cand & ~outlier)
        hmm = _build(c, steps, loge_all, x, y, model, s)
        best, gamma, start, alpha, beta = decode(hmm.coff, hmm.loge, hmm.poff, hmm.logt)
        drop = _outliers(start, steps, s.outlier_run)
        if not len(drop) or n_pass == MAX_PASSES - 1:
            break  # the last pass decoded is the result: nothing set aside after it
        outlier[drop] = True
    status = np.where(~has_pos, NO_POSITION, np.where(outlier, OUTLIER, np.where(with_cand, MATCHED, NO_CANDIDATE)))
    result = assemble(net, model.geo, model.routes, c, hmm, (best, gamma, start, alpha, beta), t, lat, lon, status)
    result.summary["settings"] = asdict(s)
    result.summary["crs_epsg"] = model.geo.projector.epsg
    return result
