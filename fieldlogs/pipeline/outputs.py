"""Writing and reading pipeline outputs: positions and events (Parquet + CSV), summary.json.

The CSV files are pandas' ``to_csv(index=False, lineterminator="\\n")`` bytes, written by the
columnar writer :mod:`dbtools.csvwrite`.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pandas as pd

from dbtools.atomic import atomic_folder
from dbtools.csvwrite import write_csv
from schemas.errors import InputError
from schemas.jsonable import jsonable


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
    import pyarrow as pa
    import pyarrow.parquet as pq

    with atomic_folder(out, force=force, inputs=inputs) as tmp:
        for name, frame in (("positions", positions), ("events", events)):
            pq.write_table(
                pa.Table.from_pandas(frame, preserve_index=False), tmp / f"{name}.parquet", compression="zstd"
            )
            write_csv(frame, tmp / f"{name}.csv")
        (tmp / "summary.json").write_text(
            json.dumps(jsonable(summary), indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
        )
    return Path(out)


def read_summary(out: Path) -> dict[str, Any]:
    p = Path(out) / "summary.json"
    try:
        data: dict[str, Any] = json.loads(p.read_text(encoding="utf-8"))
        return data
    except FileNotFoundError as exc:
        raise InputError("no summary.json (not a pipeline output folder)", path=p) from exc
    except json.JSONDecodeError as exc:
        raise InputError(f"summary.json is not valid JSON: {exc}", path=p) from exc
