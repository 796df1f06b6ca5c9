"""What one run tells the survey: its balise reads, its passes and its curvature trace.

The run is replayed through the positioning pipeline (:func:`fieldlogs.pipeline.run.run_pipeline`)
against the DB under test; everything below is read from its result (positions, odometry,
the feature unit's curvature trace ``κ = (ωz − b)/v`` with the yaw bias ``b`` removed,
cycles) — nothing in the pipeline is changed.

**Segments.** Cycles with a position (determined or uncertain) on one line/track and one
cab direction form a *segment* — on a network, also cycles on one track off every line
(a crossover, a connecting curve: its ``track_id``, no line), whose place is the distance
along that track (``pos_m``) in the place of km; each segment carries the network track
(``track_id``) of its first cycle; its *motion* σ = ±1 is the sign of km per metre of travel
(the km change from its first to its last cycle; a segment that moves less than 50 m has
none and is not used). The first segment of a cab direction is extended *backwards* over
the undetermined cycles before it by dead reckoning, km(d) = km_first − σ·(d_first − d), up
to ``extrapolate_m``: offline, the first initial pair of a run also locates the telegrams
and balises before it.

**Reads.** Each telegram is placed at the km the pipeline had just before it (the cycle
before the telegram, dead-reckoned to its time: the pipeline's "computed km" of [S003
§4.5], before the correction it may cause) and identified by content and place: the DB
balise of the same kind — I1 by line code, I2 by station code and track, C by signal type
on the segment's line/track — whose track runs in the segment's direction of motion and
whose km is nearest, within ``match_window_m``. This is the pipeline's identification
made positional: a C balise after a pair whose I1 was not read is still identified
(the pipeline, which identifies C balises by the travel since the last pair, cannot).
Telegrams with no such balise are *unknown* (candidates for the DB); a telegram read
against the track's direction is not used. A G telegram (a balise of a European group) is
identified by its NID_C, NID_BG and N_PIG alone (:mod:`fieldlogs.survey.dbindex`); on a
track off every line no I1/I2/C telegram is identified (their DB place is a line km). Every
read carries the ``track_id`` the run was on.

**Passes.** A DB balise on a segment's line/track whose track runs in the segment's
direction is *passed* when the segment's km covers it with ``pass_margin_m`` plus the
position's margin to spare on both sides [S003 §6 ③: an unpowered balise shows as a pass
without a read]; the pass time is when the km first reaches it. It is *read* when a read of
that balise lies in the same segment. Only segments in which the run identified at least
one balise have passes: a run without a balise stream, or whose reader was dead, says
nothing about the balises.

**Curvature.** κ samples (at the cycle's mid travel, SPEC §5.3) with a speed of at least
``min_speed_kmh`` (and the pipeline's feature ``min_speed_kmh``) are kept where a curve may be: within
``curve_pad_m`` of a sample with |κ| ≥ (1 − tol)/``max_radius_m`` or of a DB feature span
(on a track off every line, of its ``track_feature_points`` by pos; along a line, also of
the ``track_feature_points`` of its tracks on the line's km, :mod:`fieldlogs.survey.trackform`);
the travel intervals with a usable κ are kept too (coverage). Their km is only computed
by the aggregation (:mod:`fieldlogs.survey.trajectory`), from the balises as surveyed.

**Wheels.** The run's wheel scale from its radar calibration and from its GNSS (or D-GPS)
along-track positions on the segments (:mod:`fieldlogs.survey.wheelaids`); the balise
intervals' scale needs every run and is the aggregation's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from fieldlogs.gisverify.evidence import RunEvidence, fixes_from_result
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.geometry import VehicleGeometry
from fieldlogs.pipeline.run import PipelineResult, clean_stream, run_pipeline
from fieldlogs.replay.network import DbRef, load_network
from fieldlogs.runs.handle import Run, read_run
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.dbindex import BaliseIndex, balise_index
from fieldlogs.survey.groups import PLACEMENT_COLUMNS, TrackTrace, group_passes, group_places, run_placements
from fieldlogs.survey.trackform import km_features
from fieldlogs.survey.wheelaids import AidScale, SegmentSpan, radar_scale, run_gnss_scale
from schemas.enums import BaliseKind, PositionState
from schemas.errors import InputError, TrainposError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
#: A segment moving less than this has no direction of motion [m].
MIN_MOTION_M = 50.0
#: Gaps in the usable κ shorter than this still count as covered [m].
COVERAGE_GAP_M = 20.0
READ_COLUMNS = (
    "t",
    "kind",
    "tel_line_code",
    "tel_station_code",
    "tel_track",
    "tel_signal_type",
    "seg",
    "d_m",
    "allowance_m",
    "motion",
    "cab",
    "km_est_m",
    "balise_id",
    "line_code",
    "track",
    "track_id",
    "match_m",
    "status",
)
#: ``status`` of a read.
IDENTIFIED, UNKNOWN, UNLOCATED, WRONG_DIRECTION = "identified", "unknown", "unlocated", "wrong_direction"
SEGMENT_COLUMNS = (
    "seg",
    "line_code",
    "track",
    "track_id",
    "motion",
    "cab",
    "t0",
    "t1",
    "d0_m",
    "d1_m",
    "km0_m",
    "km1_m",
)
PASS_COLUMNS = ("balise_id", "seg", "t_pass", "km_pass_m", "read")


@dataclass
class RunSurvey:
    """The survey's view of one run (module docstring); picklable, compact."""

    run_id: str
    folder: str
    vehicle_id: str
    start_time: str
    wheel_diameter_m: float
    reader_x_m: float
    duration_s: float
    distance_m: float
    segments: pd.DataFrame
    reads: pd.DataFrame
    passes: pd.DataFrame
    kappa: pd.DataFrame
    """seg, x_m (travel), kappa (left + in the travel direction) [1/m]."""
    coverage: pd.DataFrame
    """seg, x0_m, x1_m: travel intervals with a usable κ."""
    gis: RunEvidence | None = None
    counts: dict[str, int] = field(default_factory=dict)
    radar: AidScale | None = None
    """The wheel scale from the radar's calibration (:mod:`fieldlogs.survey.wheelaids`)."""
    gnss: AidScale | None = None
    """The wheel scale from GNSS or D-GPS along-track positions."""
    group_placements: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=list(PLACEMENT_COLUMNS)))
    """Reads of G balises off every line placed from the run's earlier position (:mod:`fieldlogs.survey.groupfix`)."""


@dataclass
class _Seg:
    """One segment's cycles [ia, ib) and its backward extension to cycle ``ie``."""

    ia: int
    ib: int
    ie: int
    line_code: str
    track: str
    motion: int
    cab: int
    track_id: str = ""
    """The network track of the segment's first cycle (its only one off a line)."""


def _text(s: pd.Series) -> npt.NDArray[np.object_]:
    """Strings as an object array, "" where missing."""
    return np.asarray(s.to_numpy(dtype=object, na_value=""), dtype=object)


def _codes(s: pd.Series) -> tuple[IntArray, npt.NDArray[np.object_]]:
    """Integer codes of a text column (−1: missing or empty) and the texts they stand for."""
    codes, uniques = pd.factorize(s, use_na_sentinel=True)
    texts = np.asarray([str(u) for u in uniques], dtype=object)
    codes = np.asarray(codes, dtype=np.int64)
    empty = np.flatnonzero(texts == "")
    if empty.size:
        codes = np.where(np.isin(codes, empty), -1, codes)
    return codes, texts


def _stretch_start(known: npt.NDArray[np.bool_], cab_i: IntArray) -> IntArray:
    """For every cycle, the first cycle of the stretch of equal ``known`` and cab it is in."""
    n = known.size
    change = np.ones(n, dtype=bool)
    change[1:] = (known[1:] != known[:-1]) | (cab_i[1:] != cab_i[:-1])
    return np.asarray(np.maximum.accumulate(np.where(change, np.arange(n), 0)), dtype=np.int64)


def coordinate(pos: pd.DataFrame) -> tuple[FloatArray, npt.NDArray[np.object_]]:
    """Per cycle the place the survey works in — the line km, or on a track off every line
    the distance along it (``pos_m``) — and the cycle's ``track_id`` ("" where none)."""
    km = pos["km_m"].to_numpy(dtype=float)
    tid = _text(pos["track_id"]) if "track_id" in pos else np.full(len(pos), "", dtype=object)
    if "pos_m" in pos:
        off = (_text(pos["line_code"]) == "") & (tid != "")
        km = np.where(off, pos["pos_m"].to_numpy(dtype=float, na_value=np.nan), km)
    return np.asarray(km, dtype=float), tid


def find_segments(pos: pd.DataFrame, d: FloatArray, cab: npt.NDArray[Any], extrapolate_m: float) -> list[_Seg]:
    """Segments of the module docstring (vectorised over cycles, a loop over segments)."""
    n = len(pos)
    if n == 0:
        return []
    (lc, lines), (tc, tracks) = _codes(pos["line_code"]), _codes(pos["track"])
    ic, ids = _codes(pos["track_id"]) if "track_id" in pos else (np.full(n, -1, dtype=np.int64), np.empty(0, object))
    on_line = (lc >= 0) & (tc >= 0)
    off_line = ~on_line & (ic >= 0)  # a network track along no line: keyed by its id
    known = (_text(pos["state"]) != PositionState.UNDETERMINED.value) & (on_line | off_line)
    n_line = (lines.size + 1) * (tracks.size + 1)
    key = np.where(known & on_line, lc * (tracks.size + 1) + tc, np.where(known, n_line + ic, -1))
    cab_i = np.where(np.asarray(cab) < 0, -1, 1)
    change = np.ones(n, dtype=bool)
    change[1:] = (key[1:] != key[:-1]) | (cab_i[1:] != cab_i[:-1])
    starts = np.flatnonzero(change)
    ends = np.append(starts[1:], n)
    km = coordinate(pos)[0]
    first = _stretch_start(known, cab_i)
    out: list[_Seg] = []
    for ia, ib in zip(starts.tolist(), ends.tolist(), strict=True):
        if not known[ia]:
            continue
        dk = km[ib - 1] - km[ia]
        motion = int(np.sign(dk)) if abs(dk) >= MIN_MOTION_M else 0
        ie = ia
        if ia > 0 and not known[ia - 1] and cab_i[ia - 1] == cab_i[ia]:
            j = int(first[ia - 1])  # the undetermined stretch before, with the same cab
            ie = max(j, int(np.searchsorted(d, d[ia] - extrapolate_m, side="left")))
        tid = str(ids[ic[ia]]) if ic[ia] >= 0 else ""
        line, track = (str(lines[lc[ia]]), str(tracks[tc[ia]])) if on_line[ia] else ("", "")
        out.append(_Seg(ia, ib, ie, line, track, motion, int(cab_i[ia]), tid))
    return out


@dataclass
class _Trace:
    """The arrays of one pipeline result the extraction reads."""

    t: FloatArray
    d: FloatArray
    allowance: FloatArray
    cab: npt.NDArray[np.int64]
    km: FloatArray
    """The line km; on a track off every line the distance along it (``pos_m``)."""
    margin: FloatArray
    track_id: npt.NDArray[np.object_]

    @classmethod
    def of(cls, result: PipelineResult) -> _Trace:
        pos, odo = result.positions, result.odometry
        cab = np.asarray(result.cycles.cab if result.cycles is not None else np.ones(len(pos)), dtype=np.int64)
        km, tid = coordinate(pos)
        return cls(
            pos["t"].to_numpy(dtype=float),
            np.asarray(odo.d, dtype=float),
            np.asarray(odo.allowance, dtype=float),
            np.where(cab < 0, -1, 1),
            km,
            pos["margin_m"].to_numpy(dtype=float),
            tid,
        )

    def km_at(self, g: _Seg, x: FloatArray | float) -> FloatArray:
        """Segment km at travel ``x``: the pipeline's km inside, dead reckoning before it."""
        xa = np.asarray(x, dtype=float)
        d, km = self.d[g.ia : g.ib], self.km[g.ia : g.ib]
        inside = np.interp(xa, d, km)
        return np.asarray(np.where(xa < d[0], km[0] - g.motion * (d[0] - xa), inside), dtype=float)


def segment_frame(segs: list[_Seg], tr: _Trace) -> pd.DataFrame:
    rows = [
        {
            "seg": k,
            "line_code": g.line_code,
            "track": g.track,
            "track_id": g.track_id,
            "motion": g.motion,
            "cab": g.cab,
            "t0": float(tr.t[g.ie]),
            "t1": float(tr.t[g.ib - 1]),
            "d0_m": float(tr.d[g.ie]),
            "d1_m": float(tr.d[g.ib - 1]),
            "km0_m": float(tr.km_at(g, tr.d[g.ie])),
            "km1_m": float(tr.km[g.ib - 1]),
        }
        for k, g in enumerate(segs)
    ]
    return pd.DataFrame(rows, columns=list(SEGMENT_COLUMNS))


def _segment_of(segs: list[_Seg], tr: _Trace, t: FloatArray) -> IntArray:
    """Segment (−1: none) whose extended time span holds each time ``t``."""
    out = np.full(t.size, -1, dtype=np.int64)
    for k, g in enumerate(segs):
        inside = (t >= tr.t[g.ie]) & (t <= tr.t[g.ib - 1])
        out[inside & (out < 0)] = k
    return out


def telegram_frame(run: Run) -> pd.DataFrame:
    """The balise stream as the pipeline sees it (sorted, no repeated t)."""
    tel = clean_stream(run.stream("balise"), "balise", [])
    if tel is None or not len(tel):
        return pd.DataFrame(columns=["t", "kind", "line_code", "station_code", "track", "signal_type"])
    return tel


def read_frame(
    tel: pd.DataFrame, segs: list[_Seg], tr: _Trace, index: BaliseIndex, cfg: SurveyConfig
) -> tuple[pd.DataFrame, dict[str, int]]:
    """Every telegram located and identified (module docstring, "Reads")."""
    t = tel["t"].to_numpy(dtype=float)
    seg = _segment_of(segs, tr, t)
    d_t = np.interp(t, tr.t, tr.d)
    i0 = np.clip(np.searchsorted(tr.t, t, side="left") - 1, 0, max(tr.t.size - 1, 0))
    rows: list[dict[str, Any]] = []
    counts = {"telegrams": int(t.size), IDENTIFIED: 0, UNKNOWN: 0, UNLOCATED: 0, WRONG_DIRECTION: 0}
    texts = {c: _text(tel[c]) if c in tel.columns else np.full(t.size, "", dtype=object) for c in index.CODES}
    group = {c: tel[c].to_numpy(dtype=object) if c in tel.columns else None for c in index.GROUP_CODES}
    for j in range(t.size):
        row: dict[str, Any] = {
            "t": float(t[j]),
            "kind": str(texts["kind"][j]),
            "tel_line_code": str(texts["line_code"][j]),
            "tel_station_code": str(texts["station_code"][j]),
            "tel_track": str(texts["track"][j]),
            "tel_signal_type": str(texts["signal_type"][j]),
            "seg": int(seg[j]),
            "d_m": float(d_t[j]),
            "allowance_m": float(np.interp(t[j], tr.t, tr.allowance)),
            "motion": 0,
            "cab": int(tr.cab[min(int(i0[j]) + 1, tr.t.size - 1)]),
            "km_est_m": np.nan,
            "balise_id": "",
            "line_code": "",
            "track": "",
            "track_id": str(tr.track_id[int(i0[j])]) if tr.track_id.size else "",
            "match_m": np.nan,
            "status": UNLOCATED,
        }
        rows.append(row)
        located = seg[j] >= 0 and segs[int(seg[j])].motion != 0
        if located:
            g = segs[int(seg[j])]
            ii = int(i0[j])
            km = tr.km[ii] + g.motion * (d_t[j] - tr.d[ii]) if ii >= g.ia else float(tr.km_at(g, d_t[j]))
            row.update(km_est_m=float(km), motion=g.motion, line_code=g.line_code, track=g.track)
        if row["kind"] == BaliseKind.G:  # by its group's identity, wherever the run is
            hit_g = index.identify_group({c: None if v is None else v[j] for c, v in group.items()})
            if hit_g is not None:
                row.update(balise_id=hit_g[0], line_code=hit_g[1], track=hit_g[2], status=IDENTIFIED)
            elif located:
                row["status"] = UNKNOWN
        elif located and g.line_code:
            hit = index.identify(row, g.line_code, g.track, g.motion, cfg.match_window_m)
            if hit is None:
                row["status"] = WRONG_DIRECTION if index.against(row, g.line_code, g.motion) else UNKNOWN
            else:
                row.update(balise_id=hit[0], line_code=hit[1], track=hit[2], match_m=hit[3], status=IDENTIFIED)
        elif located:  # an I1/I2/C telegram on a track off every line: its DB place is a line km
            row["status"] = UNKNOWN
        counts[row["status"]] += 1
    frame = pd.DataFrame(rows, columns=list(READ_COLUMNS))
    return frame, counts


def pass_frame(
    segs: list[_Seg], tr: _Trace, reads: pd.DataFrame, index: BaliseIndex, cfg: SurveyConfig, distance_pct: float
) -> pd.DataFrame:
    """Every pass over a DB balise (module docstring, "Passes")."""
    frames = []
    read_keys = set(zip(reads["balise_id"], reads["seg"], strict=True)) if len(reads) else set()
    reading = set(reads.loc[reads["status"] == IDENTIFIED, "seg"]) if len(reads) else set()
    for k, g in enumerate(segs):
        if g.motion == 0 or k not in reading:
            continue  # no direction, or the reader identified nothing there (absent or dead)
        b = index.on_track(g.line_code, g.track, g.motion)
        if b is None:
            continue
        x = tr.d[g.ie : g.ib]
        u = g.motion * tr.km_at(g, x)
        m = np.concatenate(
            [tr.margin[g.ia] + distance_pct / 100.0 * (tr.d[g.ia] - tr.d[g.ie : g.ia]), tr.margin[g.ia : g.ib]]
        )
        m = np.where(np.isfinite(m), m, np.inf) + cfg.pass_margin_m
        ub = g.motion * b.km
        passed = (np.min(u + m) < ub) & (np.max(u - m) > ub)
        if not passed.any():
            continue
        ub, ids = ub[passed], b.ids[passed]
        uu = np.maximum.accumulate(u)
        j = np.clip(np.searchsorted(uu, ub, side="left"), 1, uu.size - 1)
        f = np.clip((ub - uu[j - 1]) / np.maximum(uu[j] - uu[j - 1], 1e-9), 0.0, 1.0)
        tt = tr.t[g.ie : g.ib]
        t_pass = tt[j - 1] + f * (tt[j] - tt[j - 1])
        frames.append(
            pd.DataFrame(
                {
                    "balise_id": ids,
                    "seg": k,
                    "t_pass": t_pass,
                    "km_pass_m": g.motion * ub,
                    "read": [(bid, k) in read_keys for bid in ids],
                }
            )
        )
    if not frames:
        return pd.DataFrame(columns=list(PASS_COLUMNS))
    return pd.concat(frames, ignore_index=True)


def _dilate(x: FloatArray, marked: npt.NDArray[np.bool_], pad: float) -> npt.NDArray[np.bool_]:
    """Samples within ``pad`` of travel of a marked sample (``x`` non-decreasing)."""
    xm = x[marked]
    if xm.size == 0:
        return np.zeros(x.size, dtype=bool)
    j = np.searchsorted(xm, x)
    after = np.abs(xm[np.minimum(j, xm.size - 1)] - x)
    before = np.abs(x - xm[np.maximum(j - 1, 0)])
    return np.asarray(np.minimum(after, before) <= pad, dtype=bool)


def kappa_frames(
    result: PipelineResult,
    segs: list[_Seg],
    tr: _Trace,
    network: Network,
    pipeline: PipelineConfig,
    cfg: SurveyConfig,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """κ samples near curves and DB features, and the usable-κ travel intervals (module
    docstring, "Curvature")."""
    empty = (
        pd.DataFrame({"seg": pd.Series([], dtype=np.int32), "x_m": [], "kappa": pd.Series([], dtype=np.float32)}),
        pd.DataFrame(columns=["seg", "x0_m", "x1_m"]),
    )
    kappa = result.kappa
    if kappa is None or not segs:
        return empty
    d = tr.d
    x = d - 0.5 * np.diff(d, prepend=d[0])
    v = np.asarray(result.odometry.v, dtype=float)
    usable = np.isfinite(kappa) & (v * 3.6 >= max(pipeline.feature.min_speed_kmh, cfg.min_speed_kmh))
    k_detect = (1.0 - pipeline.feature.tolerance) / cfg.max_radius_m
    seg_of = np.full(d.size, -1, dtype=np.int64)
    for k, g in enumerate(segs):
        if g.motion != 0:
            seg_of[g.ie : g.ib] = k
    usable &= seg_of >= 0
    keep = _dilate(x, usable & (np.abs(np.nan_to_num(kappa)) >= k_detect), cfg.curve_pad_m)
    keep |= _feature_spans(x, segs, tr, network, cfg.curve_pad_m)
    keep &= usable
    samples = pd.DataFrame(
        {"seg": seg_of[keep].astype(np.int32), "x_m": x[keep], "kappa": kappa[keep].astype(np.float32)}
    )
    return samples, usable_intervals(x, usable, seg_of)


def usable_intervals(x: FloatArray, usable: npt.NDArray[np.bool_], seg_of: IntArray) -> pd.DataFrame:
    """Travel intervals of consecutive usable samples of one segment; gaps shorter than
    :data:`COVERAGE_GAP_M` (a few slow cycles) are bridged."""
    idx = np.flatnonzero(usable)
    if idx.size == 0:
        return pd.DataFrame({"seg": pd.Series([], dtype=np.int64), "x0_m": [], "x1_m": []})
    xs, ss = x[idx], seg_of[idx]
    brk = np.flatnonzero((np.diff(xs) > COVERAGE_GAP_M) | (np.diff(ss) != 0)) + 1
    first = np.concatenate([[0], brk])
    last = np.concatenate([brk - 1, [idx.size - 1]])
    return pd.DataFrame({"seg": ss[first], "x0_m": xs[first], "x1_m": xs[last]})


def _feature_spans(x: FloatArray, segs: list[_Seg], tr: _Trace, network: Network, pad: float) -> npt.NDArray[np.bool_]:
    """Samples whose pipeline km lies within ``pad`` of a DB feature's six rows."""
    out = np.zeros(x.size, dtype=bool)
    fp, tfp = network.feature_points, network.track_feature_points
    if not len(fp) and not len(tfp):
        return out
    along = km_features(network)  # curves held per track along a line, on its km (fieldlogs.survey.trackform)
    line_form = pd.concat([fp, along], ignore_index=True) if len(along) else fp
    spans = network.cached("survey_feature_spans", lambda: _spans(line_form) if len(line_form) else {})
    if len(tfp):  # off a line the segment's place is the pos along its track: keyed ("", track_id)
        spans = spans | network.cached("survey_track_feature_spans", lambda: _spans(features_by_pos(tfp)))
    for g in segs:
        sp = spans.get((g.line_code, g.track) if g.line_code else ("", g.track_id))
        if sp is None or g.motion == 0:
            continue
        sl = slice(g.ie, g.ib)
        km = tr.km_at(g, x[sl])
        inside = np.zeros(km.size, dtype=bool)
        lo = np.searchsorted(sp[:, 0] - pad, km, side="right") - 1
        ok = lo >= 0
        inside[ok] = km[ok] <= sp[lo[ok], 1] + pad
        out[sl] |= inside
    return out


def features_by_pos(tfp: pd.DataFrame) -> pd.DataFrame:
    """``track_feature_points`` as feature rows keyed ("", track_id), pos in the place of km."""
    return tfp.assign(line_code="", track=tfp["track_id"].astype(str), km_m=tfp["pos_m"])


def _spans(fp: pd.DataFrame) -> dict[tuple[str, str], FloatArray]:
    """(km_min, km_max) of every DB feature per line/track, sorted, overlaps merged."""
    g = fp.groupby(["line_code", "track", "feature_id"], observed=True)["km_m"].agg(["min", "max"]).reset_index()
    out: dict[tuple[str, str], FloatArray] = {}
    for (line, track), sub in g.groupby(["line_code", "track"], observed=True):
        a = sub[["min", "max"]].to_numpy(dtype=float)
        a = a[np.argsort(a[:, 0])]
        a[:, 1] = np.maximum.accumulate(a[:, 1])
        out[(str(line), str(track))] = a
    return out


def extract(
    run: Run, result: PipelineResult, network: Network, pipeline: PipelineConfig, cfg: SurveyConfig, folder: str
) -> RunSurvey:
    """The survey's view of one replayed run (module docstring)."""
    meta = run.meta
    assert meta is not None  # run_pipeline refused the run otherwise
    tr = _Trace.of(result)
    segs = find_segments(result.positions, tr.d, tr.cab, cfg.extrapolate_m)
    index = network.cached("survey_balise_index", lambda: balise_index(network))
    reads, counts = read_frame(telegram_frame(run), segs, tr, index, cfg)
    passes = pass_frame(segs, tr, reads, index, cfg, pipeline.margin.distance_pct)
    places = network.cached("survey_group_places", lambda: group_places(network))
    placed = pd.DataFrame(columns=list(PLACEMENT_COLUMNS))
    reader_x = VehicleGeometry.of(meta.vehicle).reader_x_m
    if len(places):  # the G balises of a network's groups, per track (fieldlogs.survey.groups)
        known = _text(result.positions["state"]) != PositionState.UNDETERMINED.value
        got = reads[reads["status"] == IDENTIFIED]
        more = group_passes(places, tr.t, tr.km, tr.margin, tr.track_id, known, got, cfg)
        passes = pd.concat([passes, more], ignore_index=True) if len(more) else passes
        trace = TrackTrace(tr.t, tr.d, tr.km, tr.margin, tr.track_id, tr.cab, known)
        placed = run_placements(places, trace, got, reader_x, pipeline.margin.distance_pct)
    kappa, coverage = kappa_frames(result, segs, tr, network, pipeline, cfg)
    gis = fixes_from_result(result, run.run_id)
    gis.folder = folder
    spans = [  # the GNSS wheel scale works on line km: tracks off a line are left out
        SegmentSpan(float(tr.t[g.ia]), float(tr.t[g.ib - 1]), g.line_code, g.track, g.motion, g.cab)
        for g in segs
        if g.line_code
    ]
    return RunSurvey(
        run_id=run.run_id,
        folder=folder,
        vehicle_id=str(meta.vehicle_id),
        start_time=str(meta.start_time),
        wheel_diameter_m=float(meta.wheel_diameter_m) if meta.wheel_diameter_m is not None else float("nan"),
        reader_x_m=reader_x,
        duration_s=float(tr.t[-1] - tr.t[0]) if tr.t.size else 0.0,
        distance_m=float(tr.d[-1]) if tr.d.size else 0.0,
        segments=segment_frame(segs, tr),
        reads=reads,
        passes=passes,
        kappa=kappa,
        coverage=coverage,
        gis=gis,
        counts=counts,
        radar=radar_scale(result.odometry, cfg),
        gnss=run_gnss_scale(result, network, spans, cfg),
        group_placements=placed,
    )


def survey_one(folder: str, db: DbRef, pipeline: PipelineConfig, cfg: SurveyConfig) -> RunSurvey:
    """Replayer worker: one run against the DB of ``db`` (loaded once per worker process).
    A run that cannot be used raises an :class:`InputError` naming the folder."""
    network = load_network(db)
    try:
        run = read_run(Path(folder))
        result = run_pipeline(run, network, pipeline)
    except TrainposError as exc:
        raise InputError(f"run cannot be used: {exc}", path=folder) from None
    return extract(run, result, network, pipeline, cfg, folder)
