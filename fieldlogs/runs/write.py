"""Writing run folders (SPEC §4): ``run.json`` and one file per stream, atomically under the
output rule of :mod:`dbtools.atomic`; ``logs convert`` (:func:`convert_run`) reads a run
(:mod:`fieldlogs.runs.handle`) and writes it again in the other format."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from dbtools.atomic import atomic_folder
from fieldlogs.runs.handle import RUN_JSON_NAME, Run
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.typed import LogFormat, arrow_stream_table
from schemas.enums import Severity
from schemas.errors import FindingsError, RefusedError
from schemas.findings import Finding
from schemas.logs import LOG_STREAMS
from schemas.model import Table

#: Rows per row group of a stream written as Parquet (≈ 22 min of IMU at 100 Hz): a window of a
#: long run's replay (:mod:`fieldlogs.pipeline.windows`) decodes only the groups it reaches.
STREAM_ROW_GROUP = 1 << 17


def check_output_folder(src: Path, out: Path) -> None:
    """Refuse an output folder that is, contains or lies inside the input run."""
    s, o = Path(src).resolve(), Path(out).resolve()
    if s == o:
        raise RefusedError("the output folder must differ from the input run", path=out)
    if s in o.parents:
        raise RefusedError("the output folder must not be inside the input run", path=out)
    if o in s.parents:
        raise RefusedError("the output folder must not contain the input run", path=out)


def _write_stream(path: Path, table: Table, frame: pd.DataFrame, fmt: LogFormat) -> None:
    cols = [c for c in table.column_names if c in frame.columns]
    frame = frame[cols]
    if fmt == "parquet":
        import pyarrow.parquet as pq  # lazy: heavy

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
