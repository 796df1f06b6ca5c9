"""Feature points (curves) surveyed from the runs' curvature [S000 §3.2, §4.3.2; SPEC §5.3].

**Detection** on a track's mean profile κ̄(km) (:mod:`fieldlogs.survey.curvature`, bins
with at least ``min_passes`` runs): same-sign stretches where |κ̄| ≥ (1 − tol)/``max_radius_m``
(gaps shorter than the pipeline's ``crossing_merge_m`` bridged). Each stretch's radius is
found by the pipeline's own rule, iterated to a fixed point: the body is where
|κ̄| ≥ κ_lo = (1 − tol)/R (the *lower limit*, tol = the pipeline's ``feature.tolerance``,
20 %), and R = 1 / median |κ̄| over the middle half of the body (the pipeline's
``measured_radius_m``). A body shorter than ``min_curve_m`` or a radius above
``max_radius_m`` is not a feature.

**Location.** On every pass (:mod:`fieldlogs.survey.curvature`) whose samples cover the
curve, its own lower-limit crossings — the same rule as the pipeline: the same-sign run
of |κ_n| ≥ κ_lo nearest the profile's, runs closer than ``crossing_merge_m`` merged,
crossings interpolated linearly between samples no more than ``max_gap_m`` apart — give
its entry and exit km in the running direction; passes whose crossings lie beyond
max(3 robust σ, 5 m) of the passes' median are left out, and the curve's crossings are the
mean over the others, with a 95 % interval from their spread. The exit crossing is the
pipeline's correction point.

**Comparison** with the DB's six-row features of the track (rows 3 and 4 are the entry
and exit crossings, row 3 carries R and the attribute): a DB feature overlapping a
surveyed curve is *ok* when both crossings agree within ``feature_km_tolerance_m``, the
radius within ``feature_radius_tolerance`` and the direction is the same, else *moved*
(``reason`` names what differs); a DB feature no surveyed curve overlaps is *not seen*
when at least ``min_passes`` runs covered it with a usable κ, else *unverified*; a
surveyed curve no DB feature overlaps is *new*.

**Proposal** (new and moved curves): the six rows of [S000 Table 1] as
:func:`fieldlogs.simulate.networks.synthetic.feature_rows` builds them — in running order the
transition start t_s − 20 m (straight), t_s (transition), entry crossing (left/right, R),
exit crossing (transition), transition end t_e (straight), t_e + 20 m (none). t_s, t_e
come from the mean profile: where |κ̄| crosses 0.2/R outside the crossings, extended
linearly to κ = 0 (a linear transition has κ = 0.8/R at 0.8 of its length, so
t_s = x₀.₂ − (x₀.₈ − x₀.₂)/3). A curve whose 20 m straights are not straight on the
profile (|κ̄| above the pipeline's ``straight_kappa_max``) cannot be a feature point and
is reported, not proposed.

**Tracks off every line** (key ``("", track_id)``, :mod:`fieldlogs.survey.curvature`): the
same detection, location and comparison on ``pos_m`` in the place of km, against the
track's ``track_features`` rows (``track_feature_points``); the running direction is that
of ``pos_m`` increasing; a curve row's ``track`` holds the track_id and its entry/exit
"km" columns the pos; the proposal is six ``track_feature_points`` rows (``pos_m``).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.masks import run_around
from dbtools.masks import sign_runs as shared_sign_runs
from fieldlogs.pipeline.config import FeatureConfig
from fieldlogs.survey.balises import t_quantile
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.curvature import TrackKey, TrackSamples, mean_profile
from fieldlogs.survey.extract import features_by_pos
from schemas.enums import direction_sign

FloatArray = npt.NDArray[np.float64]
OK, MOVED, NEW, NOT_SEEN, UNVERIFIED = "ok", "moved", "new", "not seen", "unverified"
#: Straight checked before and after a curve [m] (SPEC §5.3, as ``fieldlogs.simulate.networks`` builds features).
STRAIGHT_M = 20.0
#: Level of the transition fit, as a share of 1/R (the lower limit is 1 − tol).
TRANSITION_LEVEL = 0.2
#: Samples this far beyond a curve's crossings must exist in a run to locate it there [m].
COVER_M = 20.0
#: Per-run crossings within this of the runs' median are never outliers [m].
OUTLIER_MIN_M = 5.0
CURVE_COLUMNS = (
    "line_code",
    "track",
    "curve_id",
    "attribute",
    "radius_m",
    "entry_km_m",
    "exit_km_m",
    "passes",
    "entry_ci95_m",
    "exit_ci95_m",
    "radius_spread",
    "transition_start_km_m",
    "transition_end_km_m",
    "straights_ok",
)


@dataclass(frozen=True)
class Rule:
    """The curve rule shared with the pipeline plus the survey's limits."""

    tol: float
    merge_m: float
    straight_kappa: float
    cfg: SurveyConfig

    @classmethod
    def of(cls, feature: FeatureConfig, cfg: SurveyConfig) -> Rule:
        return cls(feature.tolerance, feature.crossing_merge_m, feature.straight_kappa_max, cfg)


def sign_runs(km: FloatArray, kappa: FloatArray, level: float, merge_m: float) -> list[tuple[int, int, int]]:
    """(first, last, sign) of every same-sign run where ±κ ≥ level (``km`` ascending);
    runs of one sign closer than ``merge_m`` merged."""
    return sorted((a, b - 1, sgn) for a, b, sgn in shared_sign_runs(kappa, km, level, merge_m))


def crossing(km: FloatArray, kappa: FloatArray, i_out: int, i_in: int, level: float, sgn: int) -> float:
    """km where sgn·κ passes ``level`` between sample ``i_out`` (below) and ``i_in`` (above)."""
    if i_out < 0 or i_out >= km.size:
        return float("nan")
    a, b = sgn * kappa[i_out], sgn * kappa[i_in]
    if not (np.isfinite(a) and np.isfinite(b)) or a == b:
        return float(km[i_in])
    f = float(np.clip((level - a) / (b - a), 0.0, 1.0))
    return float(km[i_out] + f * (km[i_in] - km[i_out]))


def _radius(km: FloatArray, kap: FloatArray, lo: float, hi: float) -> float:
    body = np.abs(kap[(km >= lo) & (km <= hi)])
    body = body[np.isfinite(body)]
    mid = body[body.size // 4 : body.size - body.size // 4]
    return float(1.0 / np.median(mid)) if mid.size and np.median(mid) > 0 else float("nan")


def _body(km: FloatArray, kap: FloatArray, i0: int, i1: int, sgn: int, level: float) -> tuple[float, float] | None:
    """Crossings (km) of the run of sgn·κ ≥ level that contains the peak of [i0, i1]."""
    peak = i0 + int(np.argmax(sgn * kap[i0 : i1 + 1]))
    above = sgn * kap >= level
    if not above[peak]:
        return None
    a, b = run_around(above, peak)
    return crossing(km, kap, a - 1, a, level, sgn), crossing(km, kap, b + 1, b, level, sgn)


def detect(profile: pd.DataFrame, rule: Rule) -> list[dict[str, Any]]:
    """Curves of a track's mean profile (module docstring, "Detection")."""
    prof = profile[profile["passes"] >= rule.cfg.min_passes]
    km, kap = prof["km_m"].to_numpy(dtype=float), prof["kappa"].to_numpy(dtype=float)
    detect_level = (1.0 - rule.tol) / rule.cfg.max_radius_m
    out = []
    for i0, i1, sgn in sign_runs(km, kap, detect_level, rule.merge_m):
        curve = _fixed_point(km, kap, i0, i1, sgn, rule)
        if curve is not None:
            out.append(curve)
    return out


def _fixed_point(km: FloatArray, kap: FloatArray, i0: int, i1: int, sgn: int, rule: Rule) -> dict[str, Any] | None:
    radius = 1.0 / float(np.max(sgn * kap[i0 : i1 + 1]))
    span: tuple[float, float] | None = None
    for _ in range(8):
        span = _body(km, kap, i0, i1, sgn, (1.0 - rule.tol) / radius)
        if span is None or not np.isfinite(span).all():
            return None
        new = _radius(km, kap, *span)
        if not np.isfinite(new):
            return None
        done = abs(new - radius) < 1e-3 * radius
        radius = new
        if done:
            break
    assert span is not None
    if span[1] - span[0] < rule.cfg.min_curve_m or radius > rule.cfg.max_radius_m:
        return None
    return {"sign": sgn, "radius_m": radius, "lo": span[0], "hi": span[1]}


def run_crossings(s: TrackSamples, curve: dict[str, Any], rule: Rule) -> pd.DataFrame:
    """Per pass covering the curve: its lower-limit crossings lo, hi (km ascending)."""
    level = (1.0 - rule.tol) / curve["radius_m"]
    lo, hi, sgn = curve["lo"], curve["hi"], curve["sign"]
    win = s.window(lo - rule.cfg.curve_pad_m, hi + rule.cfg.curve_pad_m)
    run_w, km_w, kap_w = s.pass_id[win], s.km[win], s.kappa[win]
    order = np.argsort(run_w, kind="stable")  # by pass, km order kept within a pass
    run_w, km_w, kap_w = run_w[order], km_w[order], kap_w[order]
    bounds = np.flatnonzero(np.r_[True, run_w[1:] != run_w[:-1], True])
    rows = []
    for a0, a1 in itertools.pairwise(bounds):
        r = run_w[a0]
        km, kap = km_w[a0:a1], kap_w[a0:a1]
        if km.size < 3 or km[0] > lo - COVER_M or km[-1] < hi + COVER_M:
            continue
        best = None
        for a, b, sg in sign_runs(km, kap, level, rule.merge_m):
            if sg != sgn or km[b] < lo or km[a] > hi:
                continue
            cost = abs(km[a] - lo) + abs(km[b] - hi)
            if best is None or cost < best[0]:
                best = (cost, a, b)
        if best is None:
            continue
        _, a, b = best
        if a < 1 or b > km.size - 2 or km[a] - km[a - 1] > rule.cfg.max_gap_m or km[b + 1] - km[b] > rule.cfg.max_gap_m:
            continue  # a crossing falls in a gap of the run's samples (a stop, a slow stretch)
        x_lo, x_hi = crossing(km, kap, a - 1, a, level, sgn), crossing(km, kap, b + 1, b, level, sgn)
        rows.append({"pass": int(r), "lo": x_lo, "hi": x_hi, "radius_m": _radius(km, kap, x_lo, x_hi)})
    return _robust(pd.DataFrame(rows, columns=["pass", "lo", "hi", "radius_m"]))


def _robust(pr: pd.DataFrame) -> pd.DataFrame:
    """Runs whose crossings lie within max(3 robust σ, ``OUTLIER_MIN_M``) of the median
    (a run that met a gust of gyro noise at a crossing would otherwise move the mean)."""
    if len(pr) < 3:
        return pr
    keep = np.ones(len(pr), dtype=bool)
    for col in ("lo", "hi"):
        x = pr[col].to_numpy(dtype=float)
        med = np.median(x)
        mad = 1.4826 * np.median(np.abs(x - med))
        keep &= np.abs(x - med) <= max(3.0 * mad, OUTLIER_MIN_M)
    return pr[keep].reset_index(drop=True)


def _transition_end(
    km: FloatArray, kap: FloatArray, x_cross: float, sgn: int, radius: float, outward: int, lower: float
) -> float:
    """Where the transition next to the crossing ``x_cross`` (at ``lower``/R) ends toward
    the straight (outward = −1: toward lower km, +1: higher km): the |κ̄| = 0.2/R crossing
    x₀.₂ extended linearly to κ = 0, x₀.₂ + outward·|x_cross − x₀.₂|·0.2/(lower − 0.2)."""
    level = TRANSITION_LEVEL / radius
    below = sgn * kap < level
    idx = np.flatnonzero(below & ((km < x_cross) if outward < 0 else (km > x_cross)))
    if idx.size == 0:
        return float("nan")
    i = int(idx[-1] if outward < 0 else idx[0])
    j = min(max(i - outward, 0), km.size - 1)
    x02 = crossing(km, kap, i, j, level, sgn)
    return float(x02 + outward * abs(x_cross - x02) * TRANSITION_LEVEL / (lower - TRANSITION_LEVEL))


def _straights_ok(km: FloatArray, kap: FloatArray, a: float, b: float, rule: Rule) -> bool:
    """Both 20 m straights outside [a, b] are straight on the profile (with the half-bin
    the binning smears)."""
    for x0, x1 in ((a - STRAIGHT_M, a), (b, b + STRAIGHT_M)):
        sel = (km >= x0 + rule.cfg.profile_bin_m) & (km <= x1 - rule.cfg.profile_bin_m)
        if not sel.any() or (np.abs(kap[sel]) > rule.straight_kappa).any():
            return False
    return True


@dataclass
class TrackCurves:
    """Surveyed curves of one track and its profile."""

    curves: pd.DataFrame
    profile: pd.DataFrame
    per_run: dict[str, pd.DataFrame] = field(default_factory=dict)


def survey_track(key: TrackKey, s: TrackSamples, rule: Rule) -> TrackCurves:
    """Detect and locate the curves of one track (module docstring)."""
    profile = mean_profile(s, rule.cfg.profile_bin_m)
    km, kap = profile["km_m"].to_numpy(dtype=float), profile["kappa"].to_numpy(dtype=float)
    sign_n = direction_sign(key[1]) if key[0] else 1  # off a line: pos increasing
    rows, per_run = [], {}
    for k, curve in enumerate(detect(profile, rule)):
        pr = run_crossings(s, curve, rule)
        if len(pr) < rule.cfg.min_passes:
            continue
        lo, hi = float(pr["lo"].mean()), float(pr["hi"].mean())
        n = len(pr)
        half = t_quantile(n - 1) / np.sqrt(n)
        radius = 1.0 / float(np.median(1.0 / pr["radius_m"].to_numpy(dtype=float)))
        ts_lo = _transition_end(km, kap, lo, curve["sign"], radius, -1, 1.0 - rule.tol)
        ts_hi = _transition_end(km, kap, hi, curve["sign"], radius, +1, 1.0 - rule.tol)
        entry, exit_ = (lo, hi) if sign_n > 0 else (hi, lo)
        cid = f"{key[0]}-{key[1]}-{k + 1:03d}" if key[0] else f"{key[1]}-{k + 1:03d}"
        rows.append(
            {
                "line_code": key[0],
                "track": key[1],
                "curve_id": cid,
                "attribute": "left" if curve["sign"] > 0 else "right",
                "radius_m": radius,
                "entry_km_m": entry,
                "exit_km_m": exit_,
                "passes": n,
                "entry_ci95_m": float(half * pr["lo" if sign_n > 0 else "hi"].std(ddof=1)),
                "exit_ci95_m": float(half * pr["hi" if sign_n > 0 else "lo"].std(ddof=1)),
                "radius_spread": float(pr["radius_m"].std(ddof=1) / radius),
                "transition_start_km_m": ts_lo if sign_n > 0 else ts_hi,
                "transition_end_km_m": ts_hi if sign_n > 0 else ts_lo,
                "straights_ok": bool(np.isfinite([ts_lo, ts_hi]).all() and _straights_ok(km, kap, ts_lo, ts_hi, rule)),
            }
        )
        per_run[cid] = pr
    return TrackCurves(pd.DataFrame(rows, columns=list(CURVE_COLUMNS)), profile, per_run)


def db_track_features(tfp: pd.DataFrame) -> pd.DataFrame:
    """:func:`db_features` of ``track_feature_points``: keyed ``("", track_id)`` (line_code "",
    track = the track_id), pos in the place of km (module docstring)."""
    if not len(tfp):
        return db_features(tfp)
    return db_features(features_by_pos(tfp))


def db_features(fp: pd.DataFrame) -> pd.DataFrame:
    """One row per DB feature: line, track, feature_id, entry/exit km (rows 3/4), radius,
    attribute, span (rows 1–6)."""
    if not len(fp):
        return pd.DataFrame(
            columns=["line_code", "track", "feature_id", "entry_km_m", "exit_km_m", "radius_m", "attribute", "lo", "hi"]
        )
    f = fp.assign(
        line_code=fp["line_code"].astype(str), track=fp["track"].astype(str), feature_id=fp["feature_id"].astype(str)
    )
    keys = ["line_code", "track", "feature_id"]
    span = f.groupby(keys)["km_m"].agg(lo="min", hi="max")
    r3 = f[f["seq"] == 3].set_index(keys)
    r4 = f[f["seq"] == 4].set_index(keys)
    out = span.join(r3[["km_m", "radius_m", "attribute"]].rename(columns={"km_m": "entry_km_m"}))
    out = out.join(r4[["km_m"]].rename(columns={"km_m": "exit_km_m"}))
    return pd.DataFrame(out.reset_index())


def proposed_rows(curve: pd.Series, feature_id: str) -> list[dict[str, Any]]:
    """The six rows of a surveyed curve (module docstring, "Proposal"); of a track off every
    line (``line_code`` "") as ``track_feature_points`` rows (track_id, pos_m)."""
    off = not str(curve["line_code"])
    sign = 1 if off else direction_sign(str(curve["track"]))
    u = [
        sign * curve["transition_start_km_m"] - STRAIGHT_M,
        sign * curve["transition_start_km_m"],
        sign * curve["entry_km_m"],
        sign * curve["exit_km_m"],
        sign * curve["transition_end_km_m"],
        sign * curve["transition_end_km_m"] + STRAIGHT_M,
    ]
    roles = [
        ("straight", 0.0, "entry straight check starts"),
        ("transition", 0.0, "entry straight check ends"),
        (
            str(curve["attribute"]),
            round(float(curve["radius_m"]), 1),
            "curvature exceeds the lower limit (curve entry)",
        ),
        ("transition", 0.0, "curvature falls below the lower limit (curve exit)"),
        ("straight", 0.0, "exit straight check starts"),
        ("none", 0.0, "exit straight check ends"),
    ]
    where = (
        {"track_id": str(curve["track"])}
        if off
        else {"line_code": str(curve["line_code"]), "track": str(curve["track"])}
    )
    return [
        where
        | {
            "feature_id": feature_id,
            "seq": i + 1,
            "pos_m" if off else "km_m": round(float(sign * x), 1),
            "radius_m": r,
            "attribute": attr,
            "role": role,
        }
        for i, (x, (attr, r, role)) in enumerate(zip(u, roles, strict=True))
    ]
