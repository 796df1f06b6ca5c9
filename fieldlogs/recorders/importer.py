"""``logs import``: recorder files → one run folder (SPEC §4) on one time base.

1. Each source is decoded by its reader (format given or detected from the content: UBX
   sync bytes, ``$`` sentences, a RINEX header line, a ``.csv``/``.parquet`` name with a
   mapping, a ``.geojson`` point trace) into frames on absolute GPS time (``common.Decoded``).
2. The run's ``t = 0`` is the earliest absolute time of any row (navigation records
   excluded); ``t = gnss_time_s − t0`` for every stream, ``start_time`` = t0 in UTC.
   A relative recorder without a start time is aligned to t0 (noted in its provenance);
   recorder clocks with logged GNSS time pairs were already fitted by their readers.
   Navigation records dated whole 10-bit week rollovers from the observations are first
   moved onto them, others far from them named (``navweeks``).
3. ``gnss_obs`` of several receivers and ``gnss_nav`` of several files are concatenated
   (exact duplicate ephemerides dropped); any other stream from two sources is refused.
4. The vehicle file is checked (``runs.vehicle``); run.json gets vehicle_id,
   vehicle_kind, wheel_diameter_m and teeth (its tacho axle's; none for a road-rail vehicle
   or a station without one) from it, the ``vehicle`` and ``gnss`` blocks
   and ``sources`` (file, sha256, format, counts, skipped records with reasons, clock fit).
   Every receiver of ``gnss_obs`` must have an antenna.
5. Written atomically (``fieldlogs.runs.write.write_run``); nothing is written on any error.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import tzinfo
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.csv_locale import CsvLocale
from dbtools.inputs import read_head, regular_file
from fieldlogs.recorders.common import FORMATS, Decoded, sha256_of
from fieldlogs.recorders.navweeks import nav_onto_observations
from fieldlogs.recorders.timebase import gps_to_iso
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.vehicle import load_vehicle, receivers, tacho_wheel
from fieldlogs.runs.write import write_run
from schemas.enums import Severity
from schemas.errors import FindingsError, InputError, RefusedError, UsageError
from schemas.findings import Finding
from schemas.logs import LOG_STREAMS

MULTI_SOURCE = ("gnss_obs", "gnss_nav")


@dataclass
class ImportResult:
    out: str
    run_id: str
    start_time: str
    rows: dict[str, int]
    sources: list[dict[str, Any]]
    warnings: list[Finding] = field(default_factory=list)


TABLE_SUFFIXES = (".csv", ".parquet", ".txt", ".tsv")


def detect_format(path: Path) -> str:
    """nmea, ubx, rinex or csv from the file's first bytes (and name for tables)."""
    if path.suffix.lower() in TABLE_SUFFIXES:
        return "csv"
    if path.suffix.lower() == ".geojson":
        return "geojson"
    head = read_head(path)  # a few KB, whatever the file's size
    if head[:2] == b"\xb5\x62" or (b"\xb5\x62" in head[:512] and head.count(b"\xb5\x62") > 1):
        return "ubx"
    if b"RINEX VERSION / TYPE" in head[:200] or b"CRINEX VERS" in head[:200]:
        return "rinex"
    if head.lstrip()[:1] in (b"$", b"!"):
        return "nmea"
    raise InputError(
        "format not recognised (UBX, NMEA, RINEX, or CSV/Parquet with --mapping): give --format", path=path
    )


def decode(
    path: Path, fmt: str, mapping: Path | None, time_zone: str | None = None, locale: CsvLocale | None = None
) -> Decoded:
    """One source decoded; ``time_zone``: of its time stamps without a UTC offset (GeoJSON;
    a CSV mapping's own ``[time] timezone`` comes first); ``locale``: the declared convention
    of a mapped CSV (:mod:`dbtools.csv_locale`)."""
    from fieldlogs.recorders import geojson, nmea, rinex, tabular, ubx

    if fmt == "geojson":
        return geojson.read_geojson(path, _zone(time_zone))
    if fmt == "nmea":
        return nmea.read_nmea(path)
    if fmt == "ubx":
        return ubx.read_ubx(path)
    if fmt == "rinex":
        return rinex.read_rinex(path)
    if mapping is None:
        raise UsageError(f"{path}: --format csv needs --mapping MAP.toml")
    m = tabular.load_mapping(mapping)
    if time_zone is not None:
        m["time"].setdefault("timezone", time_zone)
    return tabular.read_mapped(path, m, str(mapping), locale)


def _zone(text: str | None) -> tzinfo | None:
    from fieldlogs.recorders.timebase import time_zone

    if text is None:
        return None
    try:
        return time_zone(text)
    except ValueError as exc:
        raise UsageError(f"--time-zone: {exc}") from exc


def _t0(decoded: Sequence[Decoded]) -> float:
    starts = [
        float(np.nanmin(f["gnss_time_s"].to_numpy(dtype=float)))
        for d in decoded
        for name, f in d.frames.items()
        if name != "gnss_nav" and "gnss_time_s" in f.columns and len(f) and f["gnss_time_s"].notna().any()
    ]
    if not starts:
        raise InputError(
            "no source gives an absolute time (GNSS time, Unix, UTC or a [time] start)",
            path=decoded[0].file if decoded else None,
        )
    return min(starts)


def _on_run_time(name: str, frame: pd.DataFrame, t0: float) -> pd.DataFrame:
    f = frame.copy(deep=False)
    if "recorder_s" in f.columns:
        f.insert(0, "t", f.pop("recorder_s") - float(np.nanmin(f["recorder_s"])) if len(f) else 0.0)
    elif name != "gnss_nav":
        f.insert(0, "t", f["gnss_time_s"].to_numpy(dtype=float) - t0)
    table = LOG_STREAMS[name]
    if "gnss_time_s" in f.columns and "gnss_time_s" not in table.column_names:
        f = f.drop(columns="gnss_time_s")
    for c in table.columns:
        if c.dtype == "int" and c.name in f.columns:
            f[c.name] = pd.array(np.round(f[c.name].to_numpy(dtype=float, na_value=np.nan)), dtype="Float64").astype(
                "Int64"
            )
    if name not in ("gnss_obs", "gnss_nav"):
        t = f["t"].to_numpy(dtype=float)
        if len(t) < 2 or bool((np.diff(t) >= 0).all()):
            return f.reset_index(drop=True)  # already in time order: no sort of millions of rows
        return f.sort_values("t", kind="stable").reset_index(drop=True)
    keys = ["t", "receiver", "sat", "signal"] if name == "gnss_obs" else ["sat", "toc_gps_s"]
    return f.sort_values(keys, kind="stable").reset_index(drop=True)


def _merge(decoded: Sequence[Decoded], t0: float) -> dict[str, pd.DataFrame]:
    by: dict[str, list[tuple[str, pd.DataFrame]]] = {}
    for d in decoded:
        for name, f in d.frames.items():
            by.setdefault(name, []).append((d.file, _on_run_time(name, f, t0)))
    out: dict[str, pd.DataFrame] = {}
    for name, parts in by.items():
        if len(parts) > 1 and name not in MULTI_SOURCE:
            raise UsageError(
                f"two sources give the '{name}' stream ({parts[0][0]}, {parts[1][0]}): import them into separate runs"
            )
        f = pd.concat([p for _, p in parts], ignore_index=True) if len(parts) > 1 else parts[0][1]
        if name == "gnss_nav":
            f = f.drop_duplicates().sort_values(["sat", "toc_gps_s"], kind="stable").reset_index(drop=True)
        elif name == "gnss_obs":
            f = f.sort_values(["t", "receiver", "sat", "signal"], kind="stable").reset_index(drop=True)
        out[name] = f
    return out


def _gnss_block(decoded: Sequence[Decoded]) -> dict[str, Any]:
    block: dict[str, Any] = {}
    for d in decoded:
        for k, v in d.gnss.items():
            block.setdefault(k, v)
    return block


def _check_receivers(streams: dict[str, pd.DataFrame], vehicle: dict[str, Any], vehicle_file: Path) -> None:
    obs = streams.get("gnss_obs")
    if obs is None or not len(obs):
        return
    known = set(receivers(vehicle))
    missing = sorted(set(obs["receiver"].astype(str)) - known)
    if missing:
        finding = Finding(
            "vehicle.receiver",
            Severity.ERROR,
            "vehicle",
            f"gnss_obs receiver(s) {', '.join(missing)} have no antenna in the vehicle file (antennas' receivers: "
            f"{', '.join(sorted(known)) or 'none'}); name the RINEX marker or the file after the receiver id",
            file=str(vehicle_file),
            column="antennas",
            value=missing,
            limit=sorted(known),
        )
        raise FindingsError(f"{finding.message}; nothing was written", [finding], path=vehicle_file)


def import_run(
    sources: Sequence[Path],
    out: Path,
    *,
    fmt: str = "auto",
    mapping: Sequence[Path] = (),
    vehicle: Path | None = None,
    run_id: str | None = None,
    force: bool = False,
    time_zone: str | None = None,
    locale: CsvLocale | None = None,
) -> ImportResult:
    """Decode ``sources`` and write one run folder at ``out`` (see the module docstring).

    ``mapping``: one mapping TOML per CSV/Parquet source, in the order of those sources;
    ``time_zone``: of time stamps without a UTC offset (``timebase.time_zone``); ``locale``:
    the CSV convention of the mapped CSV sources (``--delimiter``/``--decimal``)."""
    out = Path(out)
    if fmt != "auto" and fmt not in FORMATS:
        raise UsageError(f"--format {fmt}: one of auto, {', '.join(FORMATS)}")
    if out.exists() and not force:
        raise RefusedError("output folder exists; use --force to replace it", path=out)
    for s in sources:
        regular_file(Path(s), "source file")  # a FIFO, device or socket: refused, never opened
        if out.resolve() in Path(s).resolve().parents:
            raise RefusedError("a source lies inside the output folder", path=s)
    if vehicle is None:
        raise UsageError(
            "run.json needs vehicle_id, vehicle_kind, wheel_diameter_m and teeth (SPEC §4): give --vehicle VEHICLE.toml"
        )
    formats = [detect_format(Path(s)) if fmt == "auto" else fmt for s in sources]
    n_tables = formats.count("csv")
    if n_tables != len(mapping):
        raise UsageError(
            f"{n_tables} CSV/Parquet source(s) but {len(mapping)} --mapping file(s): give one mapping per "
            "table source, in the same order"
        )
    maps = iter(mapping)
    decoded = [
        decode(Path(s), f, next(maps) if f == "csv" else None, time_zone, locale)
        for s, f in zip(sources, formats, strict=True)
    ]
    nav_warnings = nav_onto_observations(decoded)  # the 10-bit week rollover, before any time is used
    t0 = _t0(decoded)
    streams = _merge(decoded, t0)
    veh, warnings = load_vehicle(vehicle, has_tacho="tacho" in streams)
    warnings = [*(f for d in decoded for f in d.findings), *nav_warnings, *warnings]
    _check_receivers(streams, veh, Path(vehicle))
    # load_vehicle refused a train, or a run with a tacho stream, without its tacho axle: a
    # wheel is missing only where run.json may go without one (a road-rail vehicle, a station)
    wheel: tuple[float | None, int | None] = tacho_wheel(veh) or (None, None)
    provenance = [d.provenance(sha256_of(Path(d.file))) for d in decoded]
    gnss = _gnss_block(decoded)
    meta = RunMeta(
        run_id=run_id or Path(sources[0]).name.split(".")[0],
        vehicle_id=str(veh["vehicle_id"]),
        vehicle_kind=str(veh["vehicle_kind"]),
        wheel_diameter_m=wheel[0],
        teeth=wheel[1],
        start_time=gps_to_iso(t0),
        notes=f"imported by trainpos logs import from {len(decoded)} source file(s)",
        vehicle=veh,
        gnss=gnss or None,
        sources=provenance,
    )
    inputs = [*sources, *mapping, *([vehicle] if vehicle is not None else [])]
    write_run(out, meta, streams, fmt="parquet", force=force, inputs=inputs)
    return ImportResult(
        str(out), meta.run_id, meta.start_time, {k: len(v) for k, v in streams.items()}, provenance, warnings
    )
