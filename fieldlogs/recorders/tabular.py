"""Vendor CSV / Parquet with a mapping TOML → one log stream (imu, tacho, radar, gps, …).

Mapping (every key documented in docs/guide/field-logs.md, "logs import"):

* ``stream`` — the target stream (``schemas.logs.LOG_STREAMS``, not gnss_obs/gnss_nav);
* ``[time]`` — ``column``, ``unit`` (s, ms, us/µs), ``base``: ``relative`` (recorder
  seconds since its start; ``start`` = ISO 8601 time of 0, else the run's start),
  ``unix`` (UTC seconds since 1970, no leap seconds), ``gps`` (continuous GPS seconds),
  ``utc`` (ISO 8601 text, leap seconds applied; stamps without an offset — a vendor's local
  time — need ``timezone``: ``UTC``, ``±HH:MM`` or an IANA name such as ``Europe/Oslo``;
  fractions of any number of digits, ``09:32:54.400`` beside ``09:32:55``); optional ``gnss_column``
  (+ ``gnss_base`` gps|unix|utc, seconds): GNSS time logged on some rows — the recorder
  clock is fitted to those pairs (``timebase.fit_clock``) and every row mapped through it;
* ``[columns]`` — target = source column name (targets not listed are taken by their own
  name when the file has them);
* ``[units]`` — per target column: g or m/s² (m/s2), deg/s or rad/s, km/h or m/s;
* ``[axes]`` — IMU mounting: body axis = ± sensor axis, e.g. ``x = "+y"``, applied to the
  accelerometer and the gyro alike; must be a rotation (a signed permutation with
  determinant +1);
* ``[offsets]`` — constants added after the unit conversion, in the stream's units;
* ``[csv]`` — ``delimiter`` (``,``, ``;``, ``tab``, ``|``) and ``decimal`` (``.``, ``,``) of a
  CSV saved in a European spreadsheet locale (``logs import --delimiter/--decimal`` come
  first); without them the convention is detected (:mod:`dbtools.csv_locale`: one
  ``source.locale`` warning; a mixed or ambiguous file refused).

A ``gps`` trace may lack the quality columns (a vendor CSV of time, latitude and longitude
only): ``fix`` absent is 1 (a position of unknown quality) where lat and lon are given and 0
elsewhere; ``nsat`` and ``hdop`` absent are left empty (unknown).

Checks that refuse the file (nothing written): a mapped column that is not in the file,
a required column neither mapped nor present, unknown units, a reflection in ``[axes]``,
an IMU whose median |a| is not gravity (units declared wrong, e.g. g as m/s²) or whose
gyro exceeds 3 rad/s at the 99th percentile (deg/s declared as rad/s).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.csv_locale import CsvLocale, csv_table, head_dialect, read_dialect, sniff_delimiter
from dbtools.inputs import not_special
from fieldlogs.recorders.common import Decoded
from fieldlogs.recorders.timebase import (
    StampError,
    fit_clock,
    iso_to_gps,
    stamps_to_gps,
    time_zone,
    unix_to_gps,
    utc_to_gps,
)
from schemas.enums import Severity
from schemas.errors import FindingsError, InputError
from schemas.findings import Finding
from schemas.frames import suggest
from schemas.logs import LOG_STREAMS, MAX_ABS_RATE_RADPS
from schemas.units import KMH, G

TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}
UNIT_FACTORS = {
    "m/s²": ("m/s²", 1.0),
    "m/s2": ("m/s²", 1.0),
    "g": ("m/s²", G),
    "rad/s": ("rad/s", 1.0),
    "deg/s": ("rad/s", math.pi / 180.0),
    "m/s": ("m/s", 1.0),
    "km/h": ("m/s", KMH),
}
IMU_ACC, IMU_GYRO = ("ax", "ay", "az"), ("wx", "wy", "wz")
#: Median |a| of an IMU must lie here [m/s²] (gravity is always measured).
GRAVITY_BAND = (7.0, 13.0)
BASES = ("relative", "unix", "gps", "utc")
#: Rows (a regular subsample) the unit plausibility statistics are taken over.
PLAUSIBILITY_SAMPLES = 200_000
SECTIONS = {"stream", "time", "columns", "units", "axes", "offsets", "csv"}
#: gps columns a trace may lack (module docstring).
GPS_QUALITY = ("fix", "nsat", "hdop")


def load_mapping(path: Path) -> dict[str, Any]:
    try:
        m = tomllib.loads(not_special(Path(path), "mapping file (TOML)").read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InputError("mapping file not found", path=path) from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from exc
    for k in m:
        if k not in SECTIONS:
            hint = suggest(k, sorted(SECTIONS))
            raise InputError(f"unknown key '{k}'" + (f" (did you mean '{hint}'?)" if hint else ""), path=path, column=k)
    stream = m.get("stream")
    if stream not in LOG_STREAMS or stream in ("gnss_obs", "gnss_nav"):
        raise InputError(f"stream = {stream!r} is not a stream a mapping can fill", path=path, column="stream")
    if not isinstance(m.get("time"), dict) or "column" not in m["time"]:
        raise InputError("[time] column = … is required", path=path, column="time.column")
    return m


def _wanted(mapping: dict[str, Any]) -> dict[str, bool]:
    """Source columns the mapping reads → numeric (True) or text (False)."""
    table = LOG_STREAMS[str(mapping["stream"])]
    cols = mapping.get("columns", {})
    out = {str(cols.get(c.name, c.name)): c.dtype in ("float", "int") for c in table.columns if c.name != "t"}
    tm = mapping["time"]
    out[str(tm["column"])] = tm.get("base", "relative") != "utc"
    if "gnss_column" in tm:
        out[str(tm["gnss_column"])] = True
    return out


def mapping_locale(mapping: dict[str, Any], mapping_file: str, given: CsvLocale | None) -> CsvLocale:
    """The CSV convention: ``given`` (the options) over the mapping's ``[csv]`` table."""
    return (given or CsvLocale()).over(csv_table(mapping.get("csv", {}), mapping_file))


def _read_table(path: Path, mapping: dict[str, Any], locale: CsvLocale) -> tuple[pd.DataFrame, Finding | None]:
    """Only the columns the mapping reads, numeric ones parsed straight to float64 (pyarrow's
    type inference costs more than the parse); a cell that is not a number falls back to
    text so that ``_numeric`` names its row. ``attrs['all_columns']``: every column name.
    A CSV in a spreadsheet locale (:mod:`dbtools.csv_locale`) is read as text and its number
    cells put in machine notation; the finding names its convention."""
    note = None
    try:
        if path.suffix.lower() == ".parquet":
            import pyarrow.parquet as pq  # lazy: heavy

            names = pq.read_schema(path).names
            keep = [c for c in _wanted(mapping) if c in names]
            frame: pd.DataFrame = pq.read_table(path, columns=keep).to_pandas()
        else:
            frame, names, note = _read_csv(path, mapping, locale)
    except FileNotFoundError as exc:
        raise InputError("source file not found", path=path) from exc
    except (OSError, ValueError) as exc:
        raise InputError(f"not a readable CSV/Parquet table: {exc}", path=path) from exc
    frame.attrs["all_columns"] = list(names)
    return frame, note


def _read_csv(path: Path, mapping: dict[str, Any], locale: CsvLocale) -> tuple[pd.DataFrame, list[str], Finding | None]:
    """:func:`_read_table` of a CSV: the frame, every column name, the locale's finding.
    Numbers are parsed by Arrow in the notation the head settles
    (:func:`dbtools.csv_locale.head_dialect`); a file it does not settle, or with a cell
    that does not parse so, is read as text: a machine-format file for ``_numeric`` to name
    the cell, a locale's judged on every cell (:func:`dbtools.csv_locale.read_dialect`)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    sniffed = sniff_delimiter(path, locale)
    opts = pcsv.ReadOptions(use_threads=False, block_size=1 << 24)
    parse = pcsv.ParseOptions(delimiter=sniffed[0])
    names = pcsv.open_csv(path, read_options=pcsv.ReadOptions(use_threads=False), parse_options=parse).schema.names
    want = {c: numeric for c, numeric in _wanted(mapping).items() if c in names}
    numbers = [c for c, n in want.items() if n]
    strings = dict.fromkeys(want, pa.string())
    dialect = head_dialect(path, numbers, locale)
    if dialect is not None:
        types = {c: pa.float64() if numeric else pa.string() for c, numeric in want.items()}
        conv = pcsv.ConvertOptions(include_columns=list(want), column_types=types, decimal_point=dialect.decimal)
        try:
            arrow = pcsv.read_csv(path, read_options=opts, parse_options=parse, convert_options=conv)
            frame = arrow.to_pandas(split_blocks=True, self_destruct=True)  # no 2-D block copy
            return frame, names, dialect.finding(path, str(mapping["stream"]))
        except pa.ArrowInvalid:
            pass
    if sniffed[0] == "," and locale.decimal != ",":  # the machine format: text, for _numeric to name the cell
        text = pcsv.ConvertOptions(include_columns=list(want), column_types=strings)
        arrow = pcsv.read_csv(path, read_options=opts, convert_options=text)
        return arrow.to_pandas(split_blocks=True, self_destruct=True), names, None
    text = pcsv.ConvertOptions(include_columns=list(want), column_types=strings, strings_can_be_null=True)
    arrow = pcsv.read_csv(path, read_options=opts, parse_options=parse, convert_options=text)
    frame, found = read_dialect(arrow.to_pandas(split_blocks=True, self_destruct=True), numbers, path, locale, sniffed)
    return frame, names, found.finding(path, str(mapping["stream"]))


def _column(path: Path, raw: pd.DataFrame, source: str, target: str) -> pd.Series:
    if source not in raw.columns:
        names = [str(c) for c in raw.attrs.get("all_columns", raw.columns)]
        hint = suggest(str(source), names)
        raise InputError(
            f"the mapping names column '{source}' (for {target}), which the file does not have"
            + (f" (did you mean '{hint}'?)" if hint else f"; columns: {', '.join(names)}"),
            path=path,
            column=str(source),
        )
    return raw[source]


def _numeric(path: Path, s: pd.Series, name: str) -> np.ndarray:
    v = pd.to_numeric(s, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
    bad = np.flatnonzero(np.isnan(v) & s.notna().to_numpy())
    if len(bad):
        raise InputError(f"'{s.iloc[bad[0]]}' is not a number", path=path, row=int(bad[0]) + 2, column=name)
    return v


def _fitted(path: Path, raw: pd.DataFrame, tm: dict[str, Any], tau: np.ndarray, dec: Decoded) -> np.ndarray:
    """Recorder times mapped to GPS time through the clock fitted to the logged pairs."""
    gcol = _numeric(path, _column(path, raw, tm["gnss_column"], "GNSS time"), str(tm["gnss_column"]))
    gb = tm.get("gnss_base", "gps")
    if gb not in ("gps", "unix", "utc"):
        raise InputError(f"gnss_base '{gb}' is not gps, unix or utc", path=path, column="time.gnss_base")
    pairs = gcol if gb == "gps" else (unix_to_gps(gcol) if gb == "unix" else utc_to_gps(gcol))
    try:
        fit = fit_clock(tau, pairs)
    except ValueError as exc:
        raise InputError(f"recorder clock: {exc}", path=path, column=str(tm["gnss_column"])) from exc
    dec.clock = {"stream": "", **fit.to_dict()}
    return fit.apply(tau)


def _utc_stamps(path: Path, col: pd.Series, tm: dict[str, Any]) -> np.ndarray:
    """ISO 8601 stamps → GPS seconds, offset-less ones in ``[time] timezone``."""
    zone = None
    if "timezone" in tm:
        try:
            zone = time_zone(str(tm["timezone"]))
        except ValueError as exc:
            raise InputError(f"time.timezone: {exc}", path=path, column="time.timezone") from exc
    try:
        return stamps_to_gps(col.tolist(), zone)
    except StampError as exc:
        raise InputError(f"time column: {exc}", path=path, row=exc.row + 2, column=str(tm["column"])) from exc


def _abs_time(path: Path, raw: pd.DataFrame, tm: dict[str, Any], dec: Decoded) -> tuple[np.ndarray, bool]:
    """(GPS seconds per row — or recorder seconds when relative without start, is absolute)."""
    col = _column(path, raw, tm["column"], "t")
    base = tm.get("base", "relative")
    if base not in BASES:
        raise InputError(f"time base '{base}' is not one of {', '.join(BASES)}", path=path, column="time.base")
    if base == "utc":
        return _utc_stamps(path, col, tm), True
    unit = tm.get("unit", "s")
    if unit not in TIME_UNITS:
        raise InputError(f"time unit '{unit}' is not one of s, ms, us", path=path, column="time.unit")
    tau = _numeric(path, col, str(tm["column"])) * TIME_UNITS[unit]
    if "gnss_column" in tm:
        return _fitted(path, raw, tm, tau, dec), True
    if base == "gps":
        return tau, True
    if base == "unix":
        return unix_to_gps(tau), True
    if "start" in tm:
        try:
            return iso_to_gps(str(tm["start"])) + tau, True
        except ValueError as exc:
            raise InputError(f"time.start: {exc}", path=path, column="time.start") from exc
    return tau, False


def _units(path: Path, m: dict[str, Any], out: dict[str, np.ndarray], stream: str) -> None:
    table = LOG_STREAMS[stream]
    for target, unit in m.get("units", {}).items():
        if target not in out:
            raise InputError(
                f"[units] names '{target}', which is not a column of {stream}", path=path, column=f"units.{target}"
            )
        if unit not in UNIT_FACTORS:
            raise InputError(
                f"unit '{unit}' is not one of {', '.join(UNIT_FACTORS)}", path=path, column=f"units.{target}"
            )
        si, factor = UNIT_FACTORS[unit]
        declared = table.column(target).unit
        if declared != si:
            raise InputError(
                f"'{target}' is in {declared or 'no unit'}, not convertible from {unit}",
                path=path,
                column=f"units.{target}",
            )
        out[target] = out[target] * factor


def _axes(path: Path, m: dict[str, Any], out: dict[str, np.ndarray]) -> None:
    axes = m.get("axes")
    if not axes:
        return
    mat = np.zeros((3, 3))
    for k, body in enumerate("xyz"):
        spec = str(axes.get(body, f"+{body}")).strip()
        if len(spec) != 2 or spec[0] not in "+-" or spec[1] not in "xyz":
            raise InputError(f"axes.{body} = '{spec}' must be ±x, ±y or ±z", path=path, column=f"axes.{body}")
        mat[k, "xyz".index(spec[1])] = 1.0 if spec[0] == "+" else -1.0
    if not np.isclose(abs(np.linalg.det(mat)), 1.0) or not np.isclose(np.linalg.det(mat), 1.0):
        raise InputError(
            "[axes] is not a rotation (a repeated axis, or a mirror image: determinant must be +1)",
            path=path,
            column="axes",
        )
    for group in (IMU_ACC, IMU_GYRO):
        src = [out[c] for c in group]
        for i, c in enumerate(group):
            j = int(np.flatnonzero(mat[i])[0])  # a signed permutation: one ±1 per row
            out[c] = src[j] if mat[i, j] > 0 else -src[j]


def _plausible(path: Path, out: dict[str, np.ndarray], stream: str, m: dict[str, Any]) -> None:
    if stream != "imu":
        return
    step = max(1, len(out["ax"]) // PLAUSIBILITY_SAMPLES)  # a regular subsample: statistics, not per-row checks
    sub = {c: out[c][::step] for c in (*IMU_ACC, *IMU_GYRO)}
    mag = np.sqrt(sub["ax"] ** 2 + sub["ay"] ** 2 + sub["az"] ** 2)
    mag = mag[np.isfinite(mag)]
    units = m.get("units", {})
    findings = []
    if len(mag) >= 10:
        med = float(np.median(mag))
        if not GRAVITY_BAND[0] <= med <= GRAVITY_BAND[1]:
            looks = ' — the data look like g: declare units ax/ay/az = "g"' if 0.7 <= med <= 1.3 else ""
            findings.append(
                Finding(
                    "import.unit",
                    Severity.ERROR,
                    "imu",
                    f"median |a| is {med:.3g} m/s² with the declared units "
                    f"({units.get('ax', 'm/s²')}), gravity expected{looks}",
                    file=str(path),
                    column="ax",
                    value=med,
                    limit=list(GRAVITY_BAND),
                )
            )
    w = np.abs(np.concatenate([sub[c] for c in IMU_GYRO]))
    w = w[np.isfinite(w)]
    if len(w) >= 10 and float(np.percentile(w, 99)) > MAX_ABS_RATE_RADPS:
        p99 = float(np.percentile(w, 99))
        findings.append(
            Finding(
                "import.unit",
                Severity.ERROR,
                "imu",
                f"99th percentile |ω| is {p99:.3g} rad/s with the declared units "
                f"({units.get('wx', 'rad/s')}): deg/s declared as rad/s?",
                file=str(path),
                column="wx",
                value=p99,
                limit=MAX_ABS_RATE_RADPS,
            )
        )
    if findings:
        raise FindingsError(
            f"units that cannot be right: {findings[0].message}; nothing was written", findings, path=path
        )


def _extract(path: Path, raw: pd.DataFrame, cols: dict[str, str], stream: str) -> dict[str, Any]:
    """Declared columns of ``stream`` from the raw table (mapped names, else their own)."""
    out: dict[str, Any] = {}
    for c in LOG_STREAMS[stream].columns:
        if c.name == "t":
            continue
        src = cols.get(c.name, c.name if c.name in raw.columns else None)
        if src is None:
            if stream == "gps" and c.name in GPS_QUALITY:
                continue  # filled by _gps_quality
            if c.required:
                raise InputError(f"{stream} needs column '{c.name}': map it in [columns]", path=path, column=c.name)
            continue
        s = _column(path, raw, src, c.name)
        out[c.name] = _numeric(path, s, str(src)) if c.dtype in ("float", "int") else s.astype("string").to_numpy()
    return out


def _gps_quality(out: dict[str, Any], n: int) -> None:
    """A gps trace without its quality columns (module docstring)."""
    if "fix" not in out:
        lat, lon = out.get("lat", np.full(n, np.nan)), out.get("lon", np.full(n, np.nan))
        out["fix"] = (np.isfinite(lat) & np.isfinite(lon)).astype(np.float64)
    for name in ("nsat", "hdop"):
        if name not in out:
            out[name] = np.full(n, np.nan)


def read_mapped(
    path: Path, mapping: dict[str, Any], mapping_file: str = "", locale: CsvLocale | None = None
) -> Decoded:
    """One vendor table → its stream with ``gnss_time_s`` (absolute) or ``recorder_s``
    (relative time without a start: the importer aligns it to the run's start).
    ``locale``: the CSV convention declared by the options (over the mapping's ``[csv]``)."""
    path = Path(path)
    dec = Decoded(str(path), "csv" if path.suffix.lower() != ".parquet" else "parquet")
    raw, note = _read_table(path, mapping, mapping_locale(mapping, mapping_file, locale))
    dec.findings += [note] if note is not None else []
    dec.records = len(raw)
    stream = str(mapping["stream"])
    table = LOG_STREAMS[stream]
    cols = mapping.get("columns", {})
    unknown = [k for k in cols if k not in table.column_names]
    if unknown:
        hint = suggest(unknown[0], table.column_names)
        raise InputError(
            f"[columns] target '{unknown[0]}' is not a column of {stream}"
            + (f" (did you mean '{hint}'?)" if hint else ""),
            path=Path(mapping_file or path),
            column=f"columns.{unknown[0]}",
        )
    out = _extract(path, raw, cols, stream)
    if stream == "gps":
        _gps_quality(out, len(raw))
    _units(path, mapping, out, stream)
    if stream == "imu":
        _axes(path, mapping, out)
    for target, off in mapping.get("offsets", {}).items():
        if target not in out:
            raise InputError(
                f"[offsets] names '{target}', which is not a column of {stream}", path=path, column=f"offsets.{target}"
            )
        out[target] = out[target] + float(off)
    _plausible(path, out, stream, mapping)
    g, absolute = _abs_time(path, raw, mapping["time"], dec)
    frame = pd.DataFrame(out)
    frame.insert(0, "gnss_time_s" if absolute else "recorder_s", g)
    if dec.clock is not None:
        dec.clock["stream"] = stream
    if not absolute:
        dec.notes.append("relative time without [time] start: aligned to the run's start")
    dec.frames[stream] = frame
    return dec
