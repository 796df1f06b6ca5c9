"""What every recorder reader returns, and the helpers they share.

A reader turns one source file into frames on absolute GNSS time: every frame has a
``gnss_time_s`` column (continuous GPS seconds, ``schemas.gnss``) except ``gnss_nav``,
which carries ``toc_gps_s``. The importer (``fieldlogs.recorders.importer``) puts all
sources on one time base and turns ``gnss_time_s`` into the run's ``t``.
"""

from __future__ import annotations

import hashlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.inputs import check_decompressed, read_input_bytes
from schemas.errors import InputError
from schemas.findings import Finding

#: Formats ``logs import`` reads.
FORMATS = ("nmea", "ubx", "rinex", "csv", "geojson")

#: The largest DOP the ``gps`` stream holds (schemas/logs.py); receivers write 99.99 for
#: "no DOP" (u-blox NMEA GGA/GSA without a fix, NAV-DOP 9999 · 0.01).
DOP_MAX = 99.9


def known_dop(dop: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """A receiver's DOP values with its "unknown" markers (above ``DOP_MAX``) as NaN."""
    d = np.asarray(dop, dtype=np.float64)
    return np.where(d > DOP_MAX, np.nan, d)


@dataclass
class Decoded:
    """One source file decoded: frames by stream name plus what was skipped and why."""

    file: str
    format: str
    frames: dict[str, pd.DataFrame] = field(default_factory=dict)
    records: int = 0
    """Records (sentences, frames, epochs, rows) read."""
    skipped: Counter[str] = field(default_factory=Counter)
    """Reason → number of records skipped (never imported)."""
    gnss: dict[str, Any] = field(default_factory=dict)
    """Navigation-header parameters (run.json ``gnss`` block)."""
    clock: dict[str, Any] | None = None
    """Recorder clock fit (``timebase.ClockFit.to_dict``) when the source had its own clock."""
    notes: list[str] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)
    """Warnings of the reading (a CSV in a spreadsheet locale: ``source.locale``)."""

    def provenance(self, sha256: str) -> dict[str, Any]:
        d: dict[str, Any] = {
            "file": self.file,
            "sha256": sha256,
            "format": self.format,
            "records": self.records,
            "counts": {k: len(v) for k, v in self.frames.items()},
            "skipped": [{"reason": r, "count": n} for r, n in sorted(self.skipped.items())],
        }
        if self.clock is not None:
            d["clock"] = self.clock
        if self.notes:
            d["notes"] = list(self.notes)
        return d


def sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with Path(path).open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_bytes(path: Path) -> bytes:
    """File content, gunzipped when it is gzip (by magic number, not by name), within the
    ``[input]`` limits: :func:`dbtools.inputs.read_input_bytes`."""
    return read_input_bytes(Path(path))


def read_text(path: Path) -> str:
    """Text of a source (gzip and Hatanaka-compressed RINEX decompressed)."""
    raw = read_bytes(path)
    head = raw[:80]
    if b"COMPACT RINEX FORMAT" in head or b"CRINEX VERS" in head:
        import hatanaka  # lazy: only for Hatanaka-compressed RINEX

        try:
            compressed, raw = len(raw), hatanaka.decompress(raw)
        except (ValueError, RuntimeError, OSError) as exc:
            raise InputError(f"Hatanaka decompression failed: {exc}", path=path) from exc
        check_decompressed(path, len(raw), compressed)
    return raw.decode("ascii", errors="replace")
