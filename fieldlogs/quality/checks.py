"""``logs check``: every problem of a run as findings (file, row, column), never an exception.

Checks, per stream (all vectorised with numpy / pandas; only the reported rows, capped per
rule, become Python objects):

* run.json fields; required streams for the vehicle kind (train: tacho and imu; road-rail:
  gps and cab); empty, unreadable, misnamed or doubled stream files;
* declared types, nulls, enumerations and ranges (``schemas.frames.check_frame``, applied to
  the suspicious rows only), e.g. |a| ≤ 30 m/s², |ω| ≤ 3 rad/s, lat/lon in the operating area;
* time: ``t`` going backwards (unsorted), duplicated ``t`` (identical rows or not), gaps
  longer than ``gap_cycles`` nominal cycles, measured sampling rate (1 / median Δt) more
  than ``rate_tolerance`` away from the declared rate;
* tacho (:func:`fieldlogs.quality.tacho.review_tacho`, the validator the possession check
  uses too): pulse counter decreasing or reset (a drop to less than half the previous count
  that does not recover at the next sample), speed jumps: pulse-derived acceleration above
  ``max_accel_mps2`` plus the quantisation of two pulses per cycle (2·k/Δt², k = π·D/teeth
  metres per pulse);
* imu: median |a| far from gravity (units: logged in g?);
* gps, with a DB: fixes outside the bounding box of the DB's GIS grid + ``area_margin_m``;
* balise: telegrams missing their fields; with a DB, unknown I1 line codes, unknown I2
  (line, station, track) pairs (the line of an I2 without one is that of the last I1
  before it) and C signal types the DB does not use;
* streams whose time spans do not overlap the others' (a stream copied from another run).

Rows are file lines (header = line 1); for Parquet the 0-based row index + 2 (see io).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.quality.clocks import clock_findings
from fieldlogs.quality.file_findings import FileFindings as _Out
from fieldlogs.quality.gnss import check_gnss_nav, check_gnss_obs, check_gnss_sbas, check_receivers
from fieldlogs.quality.radar_if import check_radar_if
from fieldlogs.quality.tacho import TACHO_RATE_HZ, TachoIssue, TachoLimits, review_tacho, time_order
from fieldlogs.runs.handle import REQUIRED_STREAMS, Run
from schemas.enums import BaliseKind, Severity
from schemas.findings import Finding
from schemas.frames import FIRST_DATA_LINE, check_frame
from schemas.logs import CAB_R_STREAMS, LOG_STREAMS
from schemas.model import Table

G = 9.80665
M_PER_DEG_LAT = 111_320.0


@dataclass(frozen=True)
class CheckLimits:
    """Tunable limits of ``logs check`` (units in the names)."""

    gap_cycles: float = 3.0
    """A gap longer than this many nominal cycles is reported."""
    rate_tolerance: float = 0.10
    """Allowed relative difference between measured and declared sampling rate."""
    max_accel_mps2: float = 5.0
    """Pulse-derived acceleration above this (plus quantisation) is a speed jump."""
    area_margin_m: float = 2000.0
    """Margin around the DB's GIS bounding box for GPS fixes."""
    overlap_tolerance_s: float = 1.0
    """Streams whose spans come closer than this still overlap."""
    gravity_band_mps2: tuple[float, float] = (7.0, 13.0)
    """Median |a| of the IMU must lie in this band (gravity is always measured)."""
    max_per_rule: int = 1000
    """Findings per rule and file; the rest are counted in one summary finding."""


@dataclass(frozen=True)
class DbRefs:
    """What ``logs check`` needs from an onboard DB."""

    origin: str
    bbox: tuple[float, float, float, float] | None
    """lat_min, lat_max, lon_min, lon_max of the GIS grid (None when it is empty)."""
    line_codes: frozenset[str]
    i2_keys: frozenset[tuple[str, str, str]]
    """(line_code, station_code, track) of every initial-position pair."""
    signal_types: frozenset[str]
    """Signal types carried by the DB's C balises."""

    @classmethod
    def from_network(cls, net: Network) -> DbRefs:
        gis, bal = net.gis, net.balises
        lat, lon = gis["lat"].to_numpy(dtype=float), gis["lon"].to_numpy(dtype=float)
        ok = ~(np.isnan(lat) | np.isnan(lon))
        bbox = (
            (float(lat[ok].min()), float(lat[ok].max()), float(lon[ok].min()), float(lon[ok].max()))
            if ok.any()
            else None
        )
        codes = set(net.lines["line_code"].dropna()) | set(bal["line_code"].dropna()) | set(gis["line_code"].dropna())
        pair = bal[bal["kind"].isin([BaliseKind.I1.value, BaliseKind.I2.value])]
        keys = set(zip(pair["line_code"], pair["station_code"], pair["track"], strict=True))
        signals = set(bal.loc[bal["kind"] == BaliseKind.C.value, "signal_type"].dropna())
        return cls(
            net.origin,
            bbox,
            frozenset(str(c) for c in codes),
            frozenset((str(a), str(b), str(c)) for a, b, c in keys),
            frozenset(str(s) for s in signals),
        )


def area_box(db: DbRefs, margin_m: float) -> list[float] | None:
    """The DB's GIS bounding box widened by ``margin_m``: [lat_min, lat_max, lon_min, lon_max]
    (None for a DB without GIS)."""
    if db.bbox is None:
        return None
    lat0, lat1, lon0, lon1 = db.bbox
    dlat = margin_m / M_PER_DEG_LAT
    dlon = margin_m / (M_PER_DEG_LAT * max(np.cos(np.radians(0.5 * (lat0 + lat1))), 0.1))
    return [lat0 - dlat, lat1 + dlat, lon0 - dlon, lon1 + dlon]


def load_db_refs(path: Path) -> DbRefs:
    """Read an onboard DB (InputError when it is not one)."""
    return DbRefs.from_network(read_network(Path(path)))


# ---------------------------------------------------------------------------------------
# helpers


def _runs(pos: np.ndarray) -> list[tuple[int, int]]:
    """Consecutive integers grouped: [3, 4, 5, 9] → [(3, 5), (9, 9)]."""
    if len(pos) == 0:
        return []
    breaks = np.flatnonzero(np.diff(pos) != 1)
    starts = np.concatenate(([0], breaks + 1))
    ends = np.concatenate((breaks, [len(pos) - 1]))
    return [(int(pos[s]), int(pos[e])) for s, e in zip(starts, ends, strict=True)]


def _const(text: str) -> Callable[[int], str]:
    return lambda _k: text


def _f(x: float) -> str:
    return f"{x:.6g}"


def _suspect_mask(table: Table, frame: pd.DataFrame) -> np.ndarray:
    """Rows that may fail a declared check (a superset, computed with numpy)."""
    mask = np.zeros(len(frame), dtype=bool)
    for c in table.columns:
        if c.name not in frame.columns:
            continue
        s = frame[c.name]
        if c.dtype in ("float", "int"):
            vals = s.to_numpy(dtype=float, na_value=np.nan)
            nan = np.isnan(vals)
            if not c.nullable:
                mask |= nan
            with np.errstate(invalid="ignore"):
                if c.min is not None:
                    mask |= vals < c.min
                if c.max is not None:
                    mask |= vals > c.max
        else:
            na = s.isna().to_numpy()
            if not c.nullable:
                mask |= na
            if c.enum is not None:
                mask |= ~na & ~s.isin(list(c.enum)).to_numpy(dtype=bool, na_value=False)
    return mask


def _duplicates(tv: np.ndarray, *, sorted_already: bool) -> tuple[np.ndarray, np.ndarray]:
    """(later occurrences of a repeated value, every occurrence of one), in file order, by sorting."""
    order = None if sorted_already else np.argsort(tv, kind="stable")
    ts = tv if order is None else tv[order]
    eq = ts[1:] == ts[:-1]
    later = np.concatenate(([False], eq))
    every = later | np.concatenate((eq, [False]))
    if order is None:
        return later, every
    dup, rep = np.zeros(len(tv), dtype=bool), np.zeros(len(tv), dtype=bool)
    dup[order] = later
    rep[order] = every
    return dup, rep


# ---------------------------------------------------------------------------------------
# per-stream checks


def _check_values(out: _Out, table: Table, frame: pd.DataFrame, read: Sequence[Finding]) -> None:
    bad = np.zeros(len(frame), dtype=bool)
    for f in read:
        if f.rule == "schema.type" and f.row is not None and 0 <= f.row - FIRST_DATA_LINE < len(frame):
            bad[f.row - FIRST_DATA_LINE] = True
    mask = _suspect_mask(table, frame) & ~bad
    if mask.any():
        out.items.extend(check_frame(table, frame[mask], file=out.file, check_keys=False, max_per_check=out.cap))


def _check_time(out: _Out, table: Table, frame: pd.DataFrame, limits: CheckLimits, rate_hz: float | None) -> None:
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    pos = np.flatnonzero(~np.isnan(t))
    tv = t[pos]
    if len(tv) < 2:
        return
    d = np.diff(tv)
    back = np.flatnonzero(d < 0) + 1
    if len(back):
        out.rows(
            "log.unsorted",
            Severity.ERROR,
            pos[back],
            lambda k: (
                f"t = {_f(tv[back[k]])} s is earlier than the row before ({_f(tv[back[k] - 1])} s): "
                "rows out of order (logs repair sorts them)"
            ),
            column="t",
            value=lambda k: float(tv[back[k]]),
            limit=None,
        )
    dup, repeated = _duplicates(tv, sorted_already=not len(back))
    if dup.any():
        # identical rows vs same t with other values: compare only the rows whose t repeats
        repeats = pos[repeated]
        sub = frame.iloc[repeats]
        exact_sub = sub.duplicated(keep="first").to_numpy()
        exact = np.zeros(len(frame), dtype=bool)
        exact[repeats[exact_sub]] = True
        dpos = pos[dup]
        same = dpos[exact[dpos]]
        other = dpos[~exact[dpos]]
        out.rows(
            "log.duplicate_row",
            Severity.ERROR,
            same,
            lambda k: f"row repeats an earlier row exactly (t = {_f(t[same[k]])} s)",
            column="t",
            value=lambda k: float(t[same[k]]),
        )
        out.rows(
            "log.duplicate_t",
            Severity.ERROR,
            other,
            lambda k: f"t = {_f(t[other[k]])} s already used by an earlier row with other values",
            column="t",
            value=lambda k: float(t[other[k]]),
        )
    if rate_hz is None:
        return
    opos, ot = time_order(t)
    if len(ot) < 2:
        return
    dts = np.diff(ot)
    nominal = 1.0 / rate_hz
    max_gap = limits.gap_cycles * nominal
    gaps = np.flatnonzero(dts > max_gap + 1e-9)
    out.rows(
        "log.gap",
        Severity.WARNING,
        opos[gaps + 1],
        lambda k: (
            f"gap of {_f(dts[gaps[k]])} s from t = {_f(ot[gaps[k]])} to {_f(ot[gaps[k] + 1])} s "
            f"(more than {limits.gap_cycles:g} cycles of {_f(nominal)} s)"
        ),
        column="t",
        value=lambda k: float(dts[gaps[k]]),
        limit=max_gap,
        what="gaps",
    )
    if len(dts) >= 3:
        med = float(np.median(dts))
        measured = 1.0 / med
        if abs(measured - rate_hz) > limits.rate_tolerance * rate_hz:
            out.add(
                "log.rate",
                Severity.ERROR,
                f"measured rate {_f(measured)} Hz (median Δt {_f(med)} s) differs from the declared "
                f"{rate_hz:g} Hz by more than {limits.rate_tolerance:.0%}",
                column="t",
                value=measured,
                limit=rate_hz,
            )


#: ``logs check`` rules of the tacho validator's findings (its other problems are the generic
#: value, time and rate checks above, and the run.json checks).
_TACHO_RULES = {
    TachoIssue.PULSE_RESET: ("log.pulse_reset", Severity.ERROR, "resets"),
    TachoIssue.PULSE_DECREASE: ("log.pulse_decrease", Severity.ERROR, "rows"),
    TachoIssue.SPEED_JUMP: ("log.speed_jump", Severity.WARNING, "speed jumps"),
}


def _check_tacho(out: _Out, run: Run, frame: pd.DataFrame, limits: CheckLimits) -> None:
    """Counter resets, decreases and speed jumps (:func:`fieldlogs.quality.tacho.review_tacho`)."""
    nominal = 1.0 / TACHO_RATE_HZ
    tacho_limits = TachoLimits(max_accel_mps2=limits.max_accel_mps2, gap_s=limits.gap_cycles * nominal)
    for f in review_tacho(frame, run.field("wheel_diameter_m"), run.field("teeth"), tacho_limits):
        if f.issue not in _TACHO_RULES:
            continue
        rule, severity, what = _TACHO_RULES[f.issue]
        detail = f.detail or _const(f.reason)
        out.rows(rule, severity, f.rows, detail, column="pulses", value=f.value, limit=f.limit, what=what)


def _check_imu(out: _Out, frame: pd.DataFrame, limits: CheckLimits) -> None:
    a = frame[["ax", "ay", "az"]].to_numpy(dtype=float, na_value=np.nan)
    mag = np.sqrt((a * a).sum(axis=1))
    mag = mag[~np.isnan(mag)]
    if len(mag) < 10:
        return
    med = float(np.median(mag))
    lo, hi = limits.gravity_band_mps2
    if not lo <= med <= hi:
        hint = " (looks like g, not m/s²)" if 0.7 <= med <= 1.3 else ""
        out.add(
            "log.unit_suspect",
            Severity.ERROR,
            f"median |a| is {med:.3g}, expected about {G:.2f} m/s² (gravity){hint}",
            column="az",
            value=med,
            limit=[lo, hi],
        )


def _check_gps(out: _Out, frame: pd.DataFrame, db: DbRefs, limits: CheckLimits) -> None:
    box = area_box(db, limits.area_margin_m)
    if box is None:
        return
    lat = frame["lat"].to_numpy(dtype=float, na_value=np.nan)
    lon = frame["lon"].to_numpy(dtype=float, na_value=np.nan)
    fix = frame["fix"].to_numpy(dtype=float, na_value=0.0)
    with np.errstate(invalid="ignore"):
        out_lat = (lat < box[0]) | (lat > box[1])
        out_lon = (lon < box[2]) | (lon > box[3])
    bad = np.flatnonzero((fix >= 1) & ~np.isnan(lat) & ~np.isnan(lon) & (out_lat | out_lon))
    runs = _runs(bad)
    starts = np.array([r[0] for r in runs], dtype=np.int64)
    out.rows(
        "log.gps_outside_area",
        Severity.WARNING,
        starts,
        lambda k: (
            f"{runs[k][1] - runs[k][0] + 1} fix(es) (lines {runs[k][0] + FIRST_DATA_LINE}–"
            f"{runs[k][1] + FIRST_DATA_LINE}) outside the DB's area ± {limits.area_margin_m:g} m, "
            f"first at {lat[runs[k][0]]:.6f}, {lon[runs[k][0]]:.6f}"
        ),
        column="lat" if len(runs) and out_lat[runs[0][0]] else "lon",
        value=lambda k: [float(lat[runs[k][0]]), float(lon[runs[k][0]])],
        limit=box,
        what="stretches of fixes",
    )


def _check_balise(out: _Out, frame: pd.DataFrame, db: DbRefs | None) -> None:
    kind = frame["kind"]
    required = {
        BaliseKind.I1.value: ("line_code",),
        BaliseKind.I2.value: ("station_code", "track"),
        BaliseKind.C.value: ("signal_type",),
    }
    for which, cols in required.items():
        is_k = (kind == which).to_numpy(dtype=bool, na_value=False)
        for c in cols:
            miss = np.flatnonzero(is_k & frame[c].isna().to_numpy())
            out.rows("log.balise_field", Severity.ERROR, miss, _const(f"{which} telegram without {c}"), column=c)
    if db is None or len(frame) == 0:
        return
    t = frame["t"].to_numpy(dtype=float, na_value=np.inf)
    order = np.argsort(t, kind="stable")  # time order; order[j] is the file row of the j-th
    f = frame.iloc[order].reset_index(drop=True)
    kinds = f["kind"].fillna("")
    txt = {c: f[c].fillna("") for c in ("line_code", "station_code", "track", "signal_type")}
    is_i1, is_i2, is_c = ((kinds == k).to_numpy(dtype=bool) for k in ("I1", "I2", "C"))

    line = txt["line_code"].to_numpy(dtype=object)
    bad_i1 = np.flatnonzero(is_i1 & (line != "") & ~txt["line_code"].isin(list(db.line_codes)).to_numpy())
    out.rows(
        "log.balise_unknown_line",
        Severity.ERROR,
        order[bad_i1],
        lambda j: f"I1 line code '{line[bad_i1[j]]}' is not in the DB ({db.origin})",
        column="line_code",
        value=lambda j: line[bad_i1[j]],
    )

    # the line of an I2 is its own, else that of the last I1 before it
    last_i1 = f["line_code"].where(pd.Series(is_i1)).ffill()
    i2_line = f["line_code"].fillna(last_i1).fillna("")
    station, track = txt["station_code"], txt["track"]
    with_line = pd.MultiIndex.from_arrays([i2_line, station, track]).isin(list(db.i2_keys))
    any_line = pd.MultiIndex.from_arrays([station, track]).isin(list({(s, tr) for _, s, tr in db.i2_keys}))
    has_fields = ((station != "") & (track != "")).to_numpy()
    known = np.where((i2_line != "").to_numpy(), with_line, any_line)
    bad_i2 = np.flatnonzero(is_i2 & has_fields & ~known)
    ln, st, tr = i2_line.to_numpy(dtype=object), station.to_numpy(dtype=object), track.to_numpy(dtype=object)
    out.rows(
        "log.balise_unknown_pair",
        Severity.ERROR,
        order[bad_i2],
        lambda j: (
            f"I2 (line {ln[bad_i2[j]] or '? (no I1 before it)'}, station {st[bad_i2[j]]}, "
            f"track {tr[bad_i2[j]]}) is not an initial-position pair of the DB"
        ),
        column="station_code",
        value=lambda j: [ln[bad_i2[j]] or None, st[bad_i2[j]], tr[bad_i2[j]]],
    )

    sig = txt["signal_type"].to_numpy(dtype=object)
    bad_c = np.flatnonzero(is_c & (sig != "") & ~txt["signal_type"].isin(list(db.signal_types)).to_numpy())
    out.rows(
        "log.balise_unknown_signal",
        Severity.ERROR,
        order[bad_c],
        lambda j: f"C signal type '{sig[bad_c[j]]}' is not used by any C balise of the DB",
        column="signal_type",
        value=lambda j: sig[bad_c[j]],
        limit=sorted(db.signal_types),
    )


def _check_overlap(run: Run, spans: dict[str, tuple[float, float]], limits: CheckLimits) -> list[Finding]:
    """Streams whose [t_min, t_max] overlaps no continuous stream's span."""
    names = list(spans)
    tol = limits.overlap_tolerance_s

    def overlaps(a: str, b: str) -> bool:
        return spans[a][0] <= spans[b][1] + tol and spans[b][0] <= spans[a][1] + tol

    continuous = [n for n in names if LOG_STREAMS[n].rate_hz is not None]
    if len(names) < 2 or not continuous:
        return []
    preferred = REQUIRED_STREAMS.get(run.vehicle_kind or "", ())
    score = {
        n: (sum(overlaps(n, o) for o in names if o != n), n in preferred, spans[n][1] - spans[n][0]) for n in continuous
    }
    ref = max(continuous, key=lambda n: score[n])
    findings = []
    for n in names:
        if n != ref and not overlaps(n, ref):
            lo, hi = spans[n]
            rlo, rhi = spans[ref]
            findings.append(
                Finding(
                    "log.no_overlap",
                    Severity.ERROR,
                    n,
                    f"t spans {_f(lo)}–{_f(hi)} s, which does not overlap {ref} ({_f(rlo)}–{_f(rhi)} s): "
                    "a stream from another run?",
                    file=str(run.stream_file(n)),
                    column="t",
                    value=[lo, hi],
                    limit=[rlo, rhi],
                )
            )
    return findings


# ---------------------------------------------------------------------------------------
# the run

#: Streams with their own checks instead of the time checks (``quality.gnss``).
GNSS_CHECKS: dict[str, Callable[[_Out, pd.DataFrame], None]] = {
    "gnss_obs": check_gnss_obs,
    "gnss_nav": check_gnss_nav,
    "gnss_sbas": check_gnss_sbas,
}


#: The sensor each of the R cab's own streams is (``imu_r`` → ``imu``…), checked as it is.
SENSOR_OF_R_STREAM = {r: f for f, r in CAB_R_STREAMS.items()}


def check_stream(run: Run, name: str, db: DbRefs | None = None, limits: CheckLimits = CheckLimits()) -> list[Finding]:
    """Read findings plus every check of one stream (empty when the stream is absent)."""
    path = run.stream_file(name)
    if path is None:
        return []
    table = LOG_STREAMS[name]
    frame = run.stream(name)
    read = list(run.stream_findings(name))
    out = _Out(name, str(path), limits.max_per_rule)
    if frame is None:
        return read
    required = name in REQUIRED_STREAMS.get(run.vehicle_kind or "", ())
    if len(frame) == 0:
        out.add(
            "log.empty_stream",
            Severity.ERROR if required else Severity.WARNING,
            "the stream has no data rows",
            value=0,
        )
        return read + out.items
    values = frame
    if name == "radar_if":  # values in FS after the declared full_scale; the I/Q convention
        values, radar_found = check_radar_if(run, frame, out.file)
        out.items += radar_found
    _check_values(out, table, values, read)
    if name in GNSS_CHECKS:
        GNSS_CHECKS[name](out, frame)
        return read + out.items
    _check_time(out, table, frame, limits, run.stream_rate_hz(name))
    sensor = SENSOR_OF_R_STREAM.get(name, name)  # the R cab's own imu_r… are checked as imu…
    if sensor == "tacho":
        _check_tacho(out, run, frame, limits)
    elif sensor == "imu":
        _check_imu(out, frame, limits)
    elif sensor == "gps" and db is not None:
        _check_gps(out, frame, db, limits)
    elif name == "balise":
        _check_balise(out, frame, db)
    return read + out.items


def check_run(run: Run | Path | str, db: DbRefs | None = None, limits: CheckLimits = CheckLimits()) -> list[Finding]:
    """Every finding of one run. Raises InputError only when the run cannot be read at all."""
    if not isinstance(run, Run):
        run = Run(Path(run))
    findings = list(run.findings)  # run.json and folder findings so far
    kind = run.vehicle_kind
    for name in REQUIRED_STREAMS.get(kind or "", ()):
        if not run.has(name):
            findings.append(
                Finding(
                    "log.missing_stream",
                    Severity.ERROR,
                    name,
                    f"a {kind} run needs a '{name}' stream ({name}.csv or {name}.parquet)",
                    file=str(run.folder),
                    value=name,
                )
            )
    spans: dict[str, tuple[float, float]] = {}
    for name in run.streams_present():
        findings.extend(check_stream(run, name, db, limits))
        frame = run.stream(name)
        if frame is not None and len(frame) and "t" in frame.columns:
            t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
            if not np.isnan(t).all():
                spans[name] = (float(np.nanmin(t)), float(np.nanmax(t)))
    findings.extend(_check_overlap(run, spans, limits))
    findings.extend(check_receivers(run))
    findings.extend(_usability(run, findings))
    findings.extend(clock_findings(run))  # the offsets the pipeline moves back (fieldlogs.quality.clocks)
    return findings


def _usability(run: Run, found: list[Finding]) -> list[Finding]:
    """The usability rule's problems the stream checks do not state (``fieldlogs.quality.usability``):
    a time base not in seconds, a tacho that is not one counter, a gyro in deg/s, an implausible
    wheel — for a train's positioning or a road-rail vehicle's possession check (an IMU in g is
    ``log.unit_suspect`` already; a column with values out of range is stated by those)."""
    from fieldlogs.quality.usability import Purpose, usability_findings

    if run.meta is None:
        return []
    purpose = Purpose.POSSESSION if run.meta.vehicle_kind == "road_rail" else Purpose.POSITIONING
    out_of_range = {(f.table, f.column) for f in found if f.rule == "schema.range"}
    extra = [
        f
        for f in usability_findings(run, purpose)
        if f.column in ("t", "pulses", "wz", "wheel_diameter_m", "teeth") and (f.table, f.column) not in out_of_range
    ]
    return [replace(f, file=f.file or str(run.folder)) for f in extra]
