"""The only readers and writers of field-log runs (SPEC §4).

A run is a folder with ``run.json`` and one file per stream (``NAME.csv`` or
``NAME.parquet``, same columns). Streams load lazily and are coerced to the declared
types of ``schemas.logs``; problems become findings (file, row, column) instead of
exceptions, so a damaged log can still be reported on and partly processed.

Row numbers in findings: for CSV the 1-based line of the file (header = line 1, first data
row = line 2). Parquet has no lines; its rows are numbered the same way, i.e. the 0-based
row index + 2, so that a CSV and its Parquet conversion report the same row numbers.

Parquet streams are read by :mod:`fieldlogs.parquet_streams` (typed column by column, a
column at a time; anything else through ``schemas.frames.coerce_frame``, which names every
bad cell; a column stored in another unit than the declared one is a finding), CSV
streams by :mod:`dbtools.typed_csv` or as text.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from dbtools.atomic import atomic_folder
from dbtools.tabular import read_raw_table
from dbtools.typed_csv import read_csv_typed
from fieldlogs.parquet_streams import (
    StreamCursor,
    parquet_windowable,
    read_parquet_stream,
    read_parquet_stream_between,
    read_parquet_table,
)
from fieldlogs.run_json import RunMeta as RunMeta  # where its callers have always found it
from fieldlogs.run_json import block_findings, load_run_json, parse_run_json, typed_fields, wheel_needed
from schemas.enums import Severity, VehicleKind
from schemas.errors import FindingsError, InputError, RefusedError
from schemas.findings import Finding
from schemas.frames import PANDAS_DTYPE, coerce_frame, suggest
from schemas.logs import LOG_STREAMS
from schemas.model import Table
from schemas.radar import parse_radar_block

LogFormat = Literal["csv", "parquet"]
STREAM_SUFFIXES = (".parquet", ".csv")
#: Rows per row group of a stream written as Parquet (≈ 22 min of IMU at 100 Hz): a window of a
#: long run's replay (:mod:`fieldlogs.pipeline.windows`) decodes only the groups it reaches.
STREAM_ROW_GROUP = 1 << 17
RUN_JSON_NAME = "run.json"
#: Files a run folder may hold besides run.json and the streams.
KNOWN_EXTRA_FILES = frozenset({"repair_log.json", "README.md", "notes.txt", "recorder"})
#: Streams a run of each vehicle kind must have (SPEC §4: no GPS on a train, no balises
#: on a road-rail vehicle).
REQUIRED_STREAMS: dict[str, tuple[str, ...]] = {
    VehicleKind.TRAIN.value: ("tacho", "imu"),
    VehicleKind.ROAD_RAIL.value: ("gps", "cab"),
}


def stream_path(folder: Path, name: str) -> Path | None:
    """The file of a stream (``.parquet`` preferred), None if absent."""
    for suffix in STREAM_SUFFIXES:
        p = Path(folder) / f"{name}{suffix}"
        if p.is_file():
            return p
    return None


def read_stream_raw(path: Path) -> pd.DataFrame:
    """A stream file as stored (Parquet typed, CSV as text)."""
    if path.suffix == ".parquet":
        frame: pd.DataFrame = read_parquet_table(path).to_pandas()
        return frame
    return read_raw_table(path)


def coerce_stream(table: Table, raw: pd.DataFrame, file: str) -> tuple[pd.DataFrame, list[Finding]]:
    """Typed stream + type findings (no range/order checks: those are ``logs check``)."""
    if all(c in raw.columns for c in table.column_names) and all(
        str(raw[c.name].dtype) == PANDAS_DTYPE[c.dtype] or (c.dtype == "float" and raw[c.name].dtype == "float64")
        for c in table.columns
    ):
        return raw[table.column_names], []  # already typed: nothing to coerce
    co = coerce_frame(table, raw, file=file)
    return co.frame, co.findings


def read_stream(table: Table, path: Path) -> tuple[pd.DataFrame, list[Finding]]:
    """One stream file → (typed frame with a 0-based positional index, findings). Raises
    InputError when the file cannot be read at all (empty, not CSV, corrupt Parquet)."""
    path = Path(path)
    if path.suffix == ".parquet":
        return read_parquet_stream(table, path)
    typed = read_csv_typed(table, path)  # numbers parsed while reading; None: read as text
    return coerce_stream(table, typed if typed is not None else read_raw_table(path), str(path))


def _run_field(data: dict[str, Any], name: str) -> Any:
    """One field of a (possibly partly broken) run.json, typed and positive, or None."""
    values, _ = typed_fields({name: data.get(name)}, Path(RUN_JSON_NAME))
    return values.get(name)


class Run:
    """One run folder; streams are read on first access and cached.

    ``findings`` holds the problems found so far: run.json fields and folder contents at
    construction, then the type findings of each stream as it is loaded. ``run.json``
    missing or not a JSON object makes the run unreadable (InputError).
    """

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise InputError("not a run folder (expected run.json and stream files)", path=self.folder)
        json_path = self.folder / RUN_JSON_NAME
        data, bad = load_run_json(json_path)
        if bad:
            raise InputError(bad[0].message, path=json_path, row=bad[0].row)
        if not isinstance(data, dict):
            raise InputError("run.json must be a JSON object", path=json_path)
        self.raw_json: dict[str, Any] = data
        self.meta, self.findings = parse_run_json(json_path)
        self.radar, radar_findings = parse_radar_block(data, json_path)
        """The run.json ``radar`` block (None when absent or unusable)."""
        self.findings.extend(radar_findings)
        self._streams: dict[str, pd.DataFrame | None] = {}
        self._stream_findings: dict[str, list[Finding]] = {}
        self._files: dict[str, Path] = {}
        self.span: tuple[float, float] | None = None
        """Set on a :meth:`window` view: only the rows with span[0] ≤ t < span[1] are read."""
        self.spooled: dict[str, Path] = {}
        self.carry_from: float | None = None
        """Set on a :meth:`window` view: where the next window will start."""
        self._cursors: dict[str, StreamCursor] = {}
        """Per stream, consecutive windows' reader (:meth:`window`; shared by the views)."""
        """CSV streams also written as Parquet (:mod:`fieldlogs.csv_spool`), which windows read."""
        self._scan()
        self.findings.extend(block_findings(data, json_path, has_tacho=self.has("tacho")))
        if self.meta is not None and self.has("tacho"):
            missing = wheel_needed(asdict(self.meta), json_path, "the run has a tacho stream")
            if missing:  # the pulses cannot be turned into metres: run.json is unusable
                self.findings.extend(missing)
                self.meta = None

    def _scan(self) -> None:
        """Find the stream files once; warn about duplicates and unknown files."""
        names = sorted(p.name for p in self.folder.iterdir())
        for name in LOG_STREAMS:
            found = [self.folder / f"{name}{s}" for s in STREAM_SUFFIXES if (self.folder / f"{name}{s}").is_file()]
            if found:
                self._files[name] = found[0]
            if len(found) > 1:
                self.findings.append(
                    Finding(
                        "log.duplicate_stream_file",
                        Severity.WARNING,
                        name,
                        f"both {found[0].name} and {found[1].name} exist; {found[0].name} is used",
                        file=str(found[1]),
                    )
                )
        expected = {f"{n}{s}" for n in LOG_STREAMS for s in STREAM_SUFFIXES} | {RUN_JSON_NAME} | KNOWN_EXTRA_FILES
        for name in names:
            if name in expected or name.startswith("."):
                continue
            stem = name.split(".", 1)[0]
            hint = suggest(stem, list(LOG_STREAMS))
            msg = f"unknown file '{name}' ignored"
            if hint:
                msg += f" (a misnamed '{hint}' stream? expected {hint}.csv or {hint}.parquet)"
            self.findings.append(
                Finding("log.unknown_file", Severity.WARNING, "run", msg, file=str(self.folder / name), value=name)
            )

    @property
    def run_id(self) -> str:
        return self.meta.run_id if self.meta else str(self.raw_json.get("run_id") or self.folder.name)

    def field(self, name: str) -> Any:
        """A run.json field, typed, even when other fields are broken (None if unusable)."""
        if self.meta is not None:
            return getattr(self.meta, name)
        return _run_field(self.raw_json, name)

    @property
    def vehicle_kind(self) -> str | None:
        kind = self.field("vehicle_kind")
        return None if kind is None else str(kind)

    def has(self, name: str) -> bool:
        return name in self._files

    def streams_present(self) -> list[str]:
        return [n for n in LOG_STREAMS if self.has(n)]

    def stream_rate_hz(self, name: str) -> float | None:
        """Nominal rate of a stream: the declared one, for ``radar_if`` 1/(2·T_pri) of run.json."""
        if name == "radar_if" and self.radar is not None:
            return self.radar.sample_rate_hz
        return LOG_STREAMS[name].rate_hz

    def stream_file(self, name: str) -> Path | None:
        return self._files.get(name)

    def stream_format(self, name: str) -> LogFormat | None:
        p = self._files.get(name)
        if p is None:
            return None
        return "parquet" if p.suffix == ".parquet" else "csv"

    def stream_findings(self, name: str) -> list[Finding]:
        """Findings from reading one stream (loads it)."""
        self.stream(name)
        return self._stream_findings.get(name, [])

    def stream(self, name: str) -> pd.DataFrame | None:
        """The typed stream, or None when the run has no such stream or it cannot be read."""
        if name not in self._streams:
            path = self._files.get(name)
            frame: pd.DataFrame | None = None
            findings: list[Finding] = []
            if path is not None and self.span is not None:
                read = self._window_of(name)  # read by window before: readable by window
                frame = read[0] if read is not None else None
            elif path is not None:
                try:
                    frame, findings = read_stream(LOG_STREAMS[name], path)
                except InputError as exc:
                    findings = [
                        Finding(
                            "log.unreadable_stream",
                            Severity.ERROR,
                            name,
                            f"cannot read the stream: {exc.message}",
                            file=str(path),
                            row=exc.row,
                        )
                    ]
            self._streams[name] = frame
            if name not in self._stream_findings:  # read again after release(): said once
                self._stream_findings[name] = findings
                self.findings.extend(findings)
        return self._streams[name]

    def window(
        self, t0: float, t1: float, streams: Iterable[str] | None = None, *, carry_from: float | None = None
    ) -> Run | None:
        """A view of this run holding only the rows with t0 ≤ t < t1 of every stream (run.json,
        files and findings so far shared), each stream (or its spooled copy) read by time window
        (:func:`fieldlogs.parquet_streams.read_parquet_stream_between`): the memory of a long
        run's replay is its window, not the whole recording. Every stream is read here, so a
        run that cannot be read by windows — a CSV stream, a Parquet column that must be
        coerced — gives None (the caller reads it whole, where the findings are made).
        :meth:`release` then :meth:`stream` reads the window again. ``streams``: only these
        are read now (the others on first access).

        Consecutive windows whose bounds never go back are read through one cursor per stream
        (:class:`fieldlogs.parquet_streams.StreamCursor`): each row group is decoded once, not
        once per window it reaches; ``carry_from`` (where the next window starts) lets the
        cursor drop at once the rows no later window needs. :meth:`close_windows` drops what
        the cursors hold."""
        wanted = set(self.streams_present() if streams is None else streams)
        view = copy.copy(self)
        view.span = (t0, t1)
        view.carry_from = carry_from
        view.findings = list(self.findings)
        view._streams = {}
        view._stream_findings = {}
        for name in (n for n in self.streams_present() if n in wanted):
            read = view._window_of(name)
            if read is None:
                return None
            view._streams[name], view._stream_findings[name] = read
            view.findings.extend(read[1])
        return view

    def windowable(self) -> bool:
        """Whether every stream can be read by time window (:meth:`window`): Parquet whose
        columns are typed as stored (from the files' schemas; no rows read)."""
        for name in self.streams_present():
            path, table = self.spooled.get(name, self._files[name]), LOG_STREAMS[name]
            if path.suffix != ".parquet" or ("t" in table.column_names and not parquet_windowable(table, path)):
                return False
        return True

    def _window_of(self, name: str) -> tuple[pd.DataFrame, list[Finding]] | None:
        """A stream's rows in the window: a held stream (:attr:`Table.held`) also every row
        before it; a table without time (the GNSS ephemerides) whole."""
        path, table = self.spooled.get(name, self._files[name]), LOG_STREAMS[name]
        if self.span is None or path.suffix != ".parquet":
            return None
        if "t" not in table.column_names:
            try:
                return read_stream(table, path)
            except InputError:
                return None
        t0, t1 = self.span
        lo = -math.inf if table.held else t0
        cursor = self._cursors.get(name)
        if cursor is None or cursor.path != path:
            cursor = self._cursors[name] = StreamCursor(table, path)
        read = cursor.between(lo, t1, None if table.held else self.carry_from)
        if read is not None:
            return read
        return read_parquet_stream_between(table, path, lo, t1)

    def lookahead(self) -> Run:
        """This run with cursors of its own (:meth:`window`), to read windows ahead of the
        ones this run's cursors are reading without moving them back."""
        ahead = copy.copy(self)
        ahead._cursors = {}
        return ahead

    def close_windows(self) -> None:
        """Drop the rows the window cursors hold (:meth:`window`)."""
        self._cursors.clear()

    def loaded(self, name: str) -> bool:
        """Whether the stream is in memory (read and not released)."""
        return name in self._streams

    def release(self, name: str) -> None:
        """Drop a loaded stream's frame, keeping its findings: a consumer that has taken
        what it needs (the pipeline, the IMU's cycle means) need not keep a long run's
        100 Hz stream in memory. A later :meth:`stream` reads the file again. Arrow's pool
        (which holds a Parquet stream's arrays) returns the freed memory at once."""
        if self._streams.pop(name, None) is not None:
            pa.default_memory_pool().release_unused()

    def load_all(self) -> dict[str, pd.DataFrame]:
        """Every readable stream present."""
        out = {}
        for name in self.streams_present():
            frame = self.stream(name)
            if frame is not None:
                out[name] = frame
        return out


def read_run(folder: Path) -> Run:
    return Run(folder)


def check_output_folder(src: Path, out: Path) -> None:
    """Refuse an output folder that is, contains or lies inside the input run."""
    s, o = Path(src).resolve(), Path(out).resolve()
    if s == o:
        raise RefusedError("the output folder must differ from the input run", path=out)
    if s in o.parents:
        raise RefusedError("the output folder must not be inside the input run", path=out)
    if o in s.parents:
        raise RefusedError("the output folder must not contain the input run", path=out)


def arrow_stream_table(table: Table, frame: pd.DataFrame) -> pa.Table:
    """Declared columns with declared Arrow types and each column's unit in its metadata."""
    arrays, fields = [], []
    for c in table.columns:
        if c.name not in frame.columns:
            continue
        s = frame[c.name]
        if c.dtype == "float":
            typ = pa.float32() if c.float32 else pa.float64()
            arr = pa.array(s.to_numpy(dtype=typ.to_pandas_dtype(), na_value=np.nan), type=typ)
        elif c.dtype == "int":
            vals = pd.to_numeric(s).astype("Int64")
            mask = vals.isna().to_numpy()
            ints = vals.to_numpy(dtype=np.int64, na_value=0)
            arr = pa.array(ints, mask=mask if mask.any() else None, type=pa.int64())
            typ = pa.int64()
        elif c.dtype == "bool":
            arr = pa.array(s.astype("boolean"), type=pa.bool_())
            typ = pa.bool_()
        else:
            arr = pa.array(s.astype("string").astype(object).where(s.notna(), None), type=pa.string())
            typ = pa.string()
        arrays.append(arr)
        fields.append(pa.field(c.name, typ, nullable=True, metadata={"unit": c.unit} if c.unit else None))
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))


def _write_stream(path: Path, table: Table, frame: pd.DataFrame, fmt: LogFormat) -> None:
    cols = [c for c in table.column_names if c in frame.columns]
    frame = frame[cols]
    if fmt == "parquet":
        # row groups of STREAM_ROW_GROUP rows: a long run's windows read the groups they reach
        pq.write_table(arrow_stream_table(table, frame), path, compression="zstd", row_group_size=STREAM_ROW_GROUP)
    else:
        frame.to_csv(path, index=False, float_format="%.10g", lineterminator="\n")


def write_run(
    folder: Path,
    meta: RunMeta,
    streams: dict[str, pd.DataFrame],
    *,
    fmt: LogFormat = "parquet",
    force: bool = False,
    extra_files: dict[str, str] | None = None,
    inputs: Iterable[Path | str] = (),
    before_publish: Callable[[Path], None] | None = None,
) -> Path:
    """Write a run folder atomically (temp folder beside it, then rename) under the output
    rule of :mod:`dbtools.atomic` (``inputs``: the command's input runs, never replaced).

    ``extra_files`` are written as text into the folder as well (e.g. ``repair_log.json``).
    ``before_publish(tmp)`` is called on the complete temporary folder before it is renamed
    into place: it may add files, and an exception it raises leaves nothing written.
    """
    folder = Path(folder)
    with atomic_folder(folder, force=force, inputs=inputs) as tmp:
        (tmp / RUN_JSON_NAME).write_text(
            json.dumps(meta.to_json(), indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
        )
        for name, frame in streams.items():
            if frame is None:
                continue
            table = LOG_STREAMS[name]
            _write_stream(tmp / f"{name}.{fmt}", table, frame, fmt)
        for name, text in (extra_files or {}).items():
            (tmp / name).write_text(text, encoding="utf-8")
        if before_publish is not None:
            before_publish(tmp)
    return folder


@dataclass
class ConvertResult:
    source: str
    out: str
    format: str
    rows: dict[str, int]
    warnings: list[Finding]


def convert_run(src: Path | str, out: Path | str, fmt: LogFormat, *, force: bool = False) -> ConvertResult:
    """Write ``src`` again as a new run folder in ``fmt`` (same columns, typed).

    Refused (FindingsError) when run.json or a stream has errors a conversion would lose,
    e.g. text in a numeric column; RefusedError when ``out`` exists (unless ``force``) or
    is, contains or lies inside ``src``.
    """
    src, out = Path(src), Path(out)
    check_output_folder(src, out)
    run = Run(src)
    if out.exists() and not force:
        raise RefusedError("output folder exists; use --force to replace it", path=out)
    streams = run.load_all()
    errors = [f for f in run.findings if f.severity == Severity.ERROR]
    if run.meta is None or errors:
        raise FindingsError(
            f"{len(errors)} error(s) would be lost or copied blindly by a conversion; "
            "run 'trainpos logs check' and fix them first; nothing was written",
            errors,
            path=src,
        )
    write_run(out, run.meta, streams, fmt=fmt, force=force, inputs=[src])
    warnings = [f for f in run.findings if f.severity == Severity.WARNING]
    return ConvertResult(str(src), str(out), fmt, {k: len(v) for k, v in streams.items()}, warnings)
