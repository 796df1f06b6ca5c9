"""The only readers and writers of field-log runs (SPEC §4).

A run is a folder with ``run.json`` and one file per stream (``NAME.csv`` or
``NAME.parquet``, same columns). Streams load lazily and are coerced to the declared
types of ``schemas.logs``; problems become findings (file, row, column) instead of
exceptions, so a damaged log can still be reported on and partly processed.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from dbtools.tabular import read_raw_table
from schemas.enums import Severity, VehicleKind
from schemas.errors import InputError, RefusedError
from schemas.findings import Finding
from schemas.frames import PANDAS_DTYPE, coerce_frame
from schemas.logs import LOG_STREAMS, RUN_JSON
from schemas.model import Table

LogFormat = Literal["csv", "parquet"]
STREAM_SUFFIXES = (".parquet", ".csv")


@dataclass
class RunMeta:
    """``run.json``."""

    run_id: str
    vehicle_id: str
    vehicle_kind: str
    wheel_diameter_m: float
    teeth: int
    start_time: str
    db_version: str | None = None
    notes: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        extra = d.pop("extra")
        return {**d, **extra}


def parse_run_json(path: Path) -> tuple[RunMeta | None, list[Finding]]:
    """Read and check ``run.json``; findings for missing or mistyped fields."""
    findings: list[Finding] = []
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None, [
            Finding("log.missing_run_json", Severity.ERROR, "run.json", "run.json is missing", file=str(path))
        ]
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        return None, [
            Finding(
                "log.bad_run_json",
                Severity.ERROR,
                "run.json",
                f"not valid JSON: {exc}",
                file=str(path),
                row=getattr(exc, "lineno", None),
            )
        ]
    if not isinstance(data, dict):
        return None, [Finding("log.bad_run_json", Severity.ERROR, "run.json", "must be a JSON object", file=str(path))]
    values: dict[str, Any] = {}
    for f in RUN_JSON:
        if f.name not in data or data[f.name] in (None, ""):
            if f.required:
                findings.append(
                    Finding(
                        "log.run_json_field",
                        Severity.ERROR,
                        "run.json",
                        f"field '{f.name}' is missing",
                        file=str(path),
                        column=f.name,
                    )
                )
            continue
        try:
            v = f.type(data[f.name])
        except (TypeError, ValueError):
            findings.append(
                Finding(
                    "log.run_json_field",
                    Severity.ERROR,
                    "run.json",
                    f"field '{f.name}' = {data[f.name]!r} is not a {f.type.__name__}",
                    file=str(path),
                    column=f.name,
                    value=data[f.name],
                )
            )
            continue
        values[f.name] = v
    kind = values.get("vehicle_kind")
    if kind is not None and kind not in {k.value for k in VehicleKind}:
        findings.append(
            Finding(
                "log.run_json_field",
                Severity.ERROR,
                "run.json",
                f"vehicle_kind '{kind}' is not train or road_rail",
                file=str(path),
                column="vehicle_kind",
                value=kind,
            )
        )
    for name in ("wheel_diameter_m", "teeth"):
        v = values.get(name)
        if v is not None and not v > 0:
            findings.append(
                Finding(
                    "log.run_json_field",
                    Severity.ERROR,
                    "run.json",
                    f"{name} must be > 0",
                    file=str(path),
                    column=name,
                    value=v,
                )
            )
    if any(f.severity == Severity.ERROR for f in findings):
        return None, findings
    known = {f.name for f in RUN_JSON}
    meta = RunMeta(**values, extra={k: v for k, v in data.items() if k not in known})  # type: ignore[arg-type]
    return meta, findings


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
        try:
            return pq.read_table(path).to_pandas()
        except (pa.ArrowInvalid, OSError) as exc:
            raise InputError(f"not a readable Parquet file: {exc}", path=path) from exc
    return read_raw_table(path)


def coerce_stream(table: Table, raw: pd.DataFrame, file: str) -> tuple[pd.DataFrame, list[Finding]]:
    """Typed stream + type findings (no range/order checks: those are ``logs check``)."""
    if all(c in raw.columns for c in table.column_names) and all(
        str(raw[c.name].dtype) == PANDAS_DTYPE[c.dtype] or (c.dtype == "float" and raw[c.name].dtype == "float64")
        for c in table.columns
    ):
        return raw[table.column_names], []  # already typed (Parquet written by us): fast path
    co = coerce_frame(table, raw, file=file)
    return co.frame, co.findings


class Run:
    """One run folder; streams are read on first access and cached."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise InputError("not a run folder (expected run.json and stream files)", path=self.folder)
        self.meta, self.findings = parse_run_json(self.folder / "run.json")
        self._streams: dict[str, pd.DataFrame | None] = {}

    @property
    def run_id(self) -> str:
        return self.meta.run_id if self.meta else self.folder.name

    def has(self, name: str) -> bool:
        return stream_path(self.folder, name) is not None

    def streams_present(self) -> list[str]:
        return [n for n in LOG_STREAMS if self.has(n)]

    def stream(self, name: str) -> pd.DataFrame | None:
        """The typed stream, or None when the run has no such stream."""
        if name not in self._streams:
            path = stream_path(self.folder, name)
            if path is None:
                self._streams[name] = None
            else:
                frame, findings = coerce_stream(LOG_STREAMS[name], read_stream_raw(path), str(path))
                self.findings.extend(findings)
                self._streams[name] = frame
        return self._streams[name]


def read_run(folder: Path) -> Run:
    return Run(folder)


def _write_stream(path: Path, table: Table, frame: pd.DataFrame, fmt: LogFormat) -> None:
    cols = [c for c in table.column_names if c in frame.columns]
    frame = frame[cols]
    if fmt == "parquet":
        pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), path, compression="zstd")
    else:
        frame.to_csv(path, index=False, float_format="%.10g", lineterminator="\n")


def write_run(
    folder: Path,
    meta: RunMeta,
    streams: dict[str, pd.DataFrame],
    *,
    fmt: LogFormat = "parquet",
    force: bool = False,
) -> Path:
    """Write a run folder atomically (temp folder beside it, then rename)."""
    folder = Path(folder)
    if folder.exists():
        if not force:
            raise RefusedError("output folder exists; use --force to replace it", path=folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        (tmp / "run.json").write_text(json.dumps(meta.to_json(), indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
        for name, frame in streams.items():
            if frame is None:
                continue
            table = LOG_STREAMS[name]
            _write_stream(tmp / f"{name}.{fmt}", table, frame, fmt)
        if folder.exists():
            old = folder.with_name(f".{folder.name}.old")
            os.replace(folder, old)
            os.replace(tmp, folder)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder
