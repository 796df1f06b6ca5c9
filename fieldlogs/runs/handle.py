"""The handle of a field-log run folder (SPEC §4): :class:`Run` (:func:`read_run`).

A run is a folder with ``run.json`` and one file per stream (``NAME.csv`` or
``NAME.parquet``, same columns). Streams load lazily and are coerced to the declared
types of ``schemas.logs``; problems become findings (file, row, column) instead of
exceptions, so a damaged log can still be reported on and partly processed.

Row numbers in findings: for CSV the 1-based line of the file (header = line 1, first data
row = line 2). Parquet has no lines; its rows are numbered the same way, i.e. the 0-based
row index + 2, so that a CSV and its Parquet conversion report the same row numbers.

Each stream file has one typed reader of its format — :class:`fieldlogs.runs.csv_reader.CsvStream`,
:class:`fieldlogs.runs.parquet_reader.ParquetStream` — which reads it whole or, as an option
of the same :meth:`read`, by time window (:meth:`Run.window`); run.json is parsed by
:mod:`fieldlogs.runs.meta`. Writing: :mod:`fieldlogs.runs.write`.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa

from fieldlogs.runs.csv_reader import CsvStream
from fieldlogs.runs.meta import block_findings, load_run_json, parse_run_json, typed_fields, wheel_needed
from fieldlogs.runs.parquet_reader import ParquetStream, Read
from fieldlogs.runs.typed import LogFormat, TimeWindow
from schemas.enums import Severity, VehicleKind
from schemas.errors import InputError
from schemas.findings import Finding
from schemas.frames import suggest
from schemas.logs import LOG_STREAMS
from schemas.radar import parse_radar_block

STREAM_SUFFIXES = (".parquet", ".csv")
RUN_JSON_NAME = "run.json"
#: Files a run folder may hold besides run.json and the streams.
KNOWN_EXTRA_FILES = frozenset({"repair_log.json", "README.md", "notes.txt", "recorder"})
#: Streams a run of each vehicle kind must have (SPEC §4: no GPS on a train, no balises
#: on a road-rail vehicle).
REQUIRED_STREAMS: dict[str, tuple[str, ...]] = {
    VehicleKind.TRAIN.value: ("tacho", "imu"),
    VehicleKind.ROAD_RAIL.value: ("gps", "cab"),
}
#: A stream file's typed reader.
StreamReader = CsvStream | ParquetStream


def _run_field(data: dict[str, Any], name: str) -> Any:
    """One field of a (possibly partly broken) run.json, typed and positive, or None."""
    values, _ = typed_fields({name: data.get(name)}, Path(RUN_JSON_NAME))
    return values.get(name)


def _reader(name: str, path: Path) -> StreamReader:
    table = LOG_STREAMS[name]
    return ParquetStream(table, path) if path.suffix == ".parquet" else CsvStream(table, path)


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
        self._readers: dict[str, StreamReader] = {}
        """Per stream, its file's reader (shared by the :meth:`window` views: consecutive
        windows go on where the last one stopped)."""
        self.span: TimeWindow | None = None
        """Set on a :meth:`window` view: only the rows with t0 ≤ t < t1 are read."""
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
                self._readers[name] = _reader(name, found[0])
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
        return name in self._readers

    def streams_present(self) -> list[str]:
        return [n for n in LOG_STREAMS if self.has(n)]

    def stream_rate_hz(self, name: str) -> float | None:
        """Nominal rate of a stream: the declared one, for ``radar_if`` 1/(2·T_pri) of run.json."""
        if name == "radar_if" and self.radar is not None:
            return self.radar.sample_rate_hz
        return LOG_STREAMS[name].rate_hz

    def stream_file(self, name: str) -> Path | None:
        reader = self._readers.get(name)
        return None if reader is None else reader.path

    def stream_format(self, name: str) -> LogFormat | None:
        reader = self._readers.get(name)
        if reader is None:
            return None
        return "parquet" if isinstance(reader, ParquetStream) else "csv"

    def stream_findings(self, name: str) -> list[Finding]:
        """Findings from reading one stream (loads it)."""
        self.stream(name)
        return self._stream_findings.get(name, [])

    def stream(self, name: str) -> pd.DataFrame | None:
        """The typed stream (on a :meth:`window` view: its rows in the window), or None when
        the run has no such stream or it cannot be read."""
        if name not in self._streams:
            frame: pd.DataFrame | None = None
            findings: list[Finding] = []
            reader = self._readers.get(name)
            if reader is not None:
                try:
                    read = reader.read(self.span)
                    if read is not None:
                        frame, findings = read
                except InputError as exc:
                    findings = [
                        Finding(
                            "log.unreadable_stream",
                            Severity.ERROR,
                            name,
                            f"cannot read the stream: {exc.message}",
                            file=str(reader.path),
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
        files and findings so far shared), each stream read by its reader with that time
        window (:class:`fieldlogs.runs.typed.TimeWindow`): the memory of a long run's replay
        is its window, not the whole recording. Every stream is read here, so a run that
        cannot be read by windows — a CSV stream not spooled (:meth:`spool`), a Parquet
        column that must be coerced — gives None (the caller reads it whole, where the
        findings are made). :meth:`release` then :meth:`stream` reads the window again.
        ``streams``: only these are read now (the others on first access).

        Consecutive windows whose bounds never go back are read on from where the last one
        stopped (each row group decoded once, :class:`fieldlogs.runs.cursor.StreamCursor`);
        ``carry_from`` (where the next window starts) lets the readers drop at once the rows
        no later window needs. :meth:`close_windows` drops what they hold."""
        wanted = set(self.streams_present() if streams is None else streams)
        view = copy.copy(self)
        view.span = TimeWindow(t0, t1, carry_from)
        view.findings = list(self.findings)
        view._streams = {}
        view._stream_findings = {}
        for name in (n for n in self.streams_present() if n in wanted):
            read: Read | None = view._readers[name].read(view.span)
            if read is None:
                return None
            view._streams[name], view._stream_findings[name] = read
            view.findings.extend(read[1])
        return view

    def windowable(self) -> bool:
        """Whether every stream can be read by time window (:meth:`window`): Parquet (or
        spooled) whose columns are typed as stored (from the files' schemas; no rows read)."""
        return all(self._readers[name].windowable() for name in self.streams_present())

    def t_span(self, name: str) -> tuple[float, float] | None:
        """(first, last) t of a stream without reading its rows (None: not known so)."""
        reader = self._readers.get(name)
        return None if reader is None else reader.t_span()

    def rows(self, name: str) -> int | None:
        """Rows of a stream readable by window, from its metadata (None: not known so)."""
        reader = self._readers.get(name)
        return None if reader is None else reader.rows()

    def spool(self, folder: Path) -> bool:
        """Spool every CSV stream into ``folder`` (:meth:`fieldlogs.runs.csv_reader.CsvStream.spool`)
        so that windows can read them; True when all of them are."""
        for name in self.streams_present():
            reader = self._readers[name]
            if isinstance(reader, CsvStream) and not reader.spool(folder):
                return False
        return True

    def spooled(self) -> dict[str, Path]:
        """The spooled copies of the CSV streams (:meth:`spool`), by stream."""
        return {
            name: r.spooled.path
            for name, r in self._readers.items()
            if isinstance(r, CsvStream) and r.spooled is not None
        }

    def lookahead(self) -> Run:
        """This run with readers of its own (:meth:`window`), to read windows ahead of the
        ones this run's readers are reading without moving them back."""
        ahead = copy.copy(self)
        ahead._readers = {name: r.fresh() for name, r in self._readers.items()}
        return ahead

    def close_windows(self) -> None:
        """Drop the rows the readers hold for the next window (:meth:`window`)."""
        for reader in self._readers.values():
            reader.close()

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
