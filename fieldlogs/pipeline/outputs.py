"""Writing and reading pipeline outputs: positions and events (Parquet + CSV), summary.json.

The CSV files are pandas' ``to_csv(index=False, lineterminator="\\n")`` bytes, written by the
columnar writer :mod:`dbtools.csvwrite`.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import pandas as pd

from dbtools.atomic import atomic_folder
from dbtools.csvwrite import csv_bytes, write_csv
from schemas.errors import InputError
from schemas.jsonable import jsonable
from schemas.model import Table
from schemas.outputs import POSITIONS


def write_results(
    out: Path,
    positions: pd.DataFrame,
    events: pd.DataFrame,
    summary: dict[str, Any],
    *,
    force: bool = False,
    inputs: Iterable[Path | str] = (),
) -> Path:
    """OUT/positions.{parquet,csv}, OUT/events.{parquet,csv}, OUT/summary.json — atomically."""
    with streamed_results(out, force=force, inputs=inputs) as sink:
        sink.add_positions(positions)
        sink.finish(events, summary)
    return Path(out)


class ResultsWriter:
    """The output files of one run written as its positions come (a long run's windows,
    :mod:`fieldlogs.pipeline.windows`): each :meth:`add_positions` is a row group of
    positions.parquet and the next rows of positions.csv, so no more than one part is ever
    in memory; :meth:`finish` writes the events and the summary. One part gives the bytes
    ``pq.write_table`` and :func:`~dbtools.csvwrite.write_csv` give the whole frame."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self._parquet: Any = None
        self._schema: Any = None
        self._csv: Any = None

    def add_positions(self, frame: pd.DataFrame) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pandas(frame, preserve_index=False)
        data = csv_bytes(frame)
        if self._parquet is None:
            self._schema = _declared_where_null(table.schema, POSITIONS)
            self._parquet = pq.ParquetWriter(self.folder / "positions.parquet", self._schema, compression="zstd")
            self._csv = (self.folder / "positions.csv").open("wb")
        else:
            data = data[data.index(b"\n") + 1 :]  # the header once
        self._parquet.write_table(table if table.schema == self._schema else table.cast(self._schema))
        self._csv.write(data)

    def finish(self, events: pd.DataFrame, summary: dict[str, Any]) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.close()
        pq.write_table(
            pa.Table.from_pandas(events, preserve_index=False), self.folder / "events.parquet", compression="zstd"
        )
        write_csv(events, self.folder / "events.csv")
        (self.folder / "summary.json").write_text(
            json.dumps(jsonable(summary), indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
        )

    def close(self) -> None:
        if self._parquet is not None:
            self._parquet.close()
            self._csv.close()
            self._parquet = self._csv = None


@contextlib.contextmanager
def streamed_results(out: Path, *, force: bool = False, inputs: Iterable[Path | str] = ()) -> Iterator[ResultsWriter]:
    """A :class:`ResultsWriter` into a temporary folder that replaces ``out`` when the block
    ends without an error (nothing of a failed run is left; an existing ``out`` needs
    ``force``)."""
    with atomic_folder(out, force=force, inputs=inputs) as tmp:
        sink = ResultsWriter(tmp)
        try:
            yield sink
        finally:
            sink.close()


def _declared_where_null(schema: Any, table: Table) -> Any:
    """The first part's Arrow schema with a column that was all missing in it (Arrow type
    null) given its declared type, so the later parts' values fit."""
    import pyarrow as pa

    arrow = {"float": pa.float64(), "int": pa.int64(), "str": pa.string(), "bool": pa.bool_()}
    declared = {c.name: arrow[c.dtype] for c in table.columns}
    fields = [f.with_type(declared[f.name]) if pa.types.is_null(f.type) and f.name in declared else f for f in schema]
    return pa.schema(fields, metadata=schema.metadata)


def read_summary(out: Path) -> dict[str, Any]:
    p = Path(out) / "summary.json"
    try:
        data: dict[str, Any] = json.loads(p.read_text(encoding="utf-8"))
        return data
    except FileNotFoundError as exc:
        raise InputError("no summary.json (not a pipeline output folder)", path=p) from exc
    except json.JSONDecodeError as exc:
        raise InputError(f"summary.json is not valid JSON: {exc}", path=p) from exc
