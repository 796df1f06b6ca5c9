"""``logs repair``: the safe, explicit repairs, written to a new run folder.

Per stream, in this order:

1. sort by ``t`` (stable: rows with the same ``t`` keep their file order);
2. drop rows that repeat an earlier row exactly;
3. drop rows whose ``t`` repeats an earlier row's with other values, keeping the first
   (in file order) — the dropped values are listed in the log by row;
4. tacho only: bridge pulse-counter resets (``checks.pulse_resets``: a drop below half of
   the previous count that stays below it at the next sample) by adding the count before
   each reset to every later row, so the pulses are cumulative again. Other drops are
   glitches: reported by ``logs check``, never changed.

Nothing else is changed: a run with unreadable cells, unreadable streams, empty ``t`` or a
broken run.json is refused (fix those by hand). The repaired run is then checked as
``logs check`` would check it, before it is published: when errors remain (a small pulse
drop, a plausibility error of run.json …: problems only a person can judge), or warnings
with ``strict``, the repair is refused too, naming them, and nothing is written. The input
folder is only read; the output is written atomically and must not exist (unless
``force``), differ from the input and not contain it or lie inside it. ``repair_log.json``
in the output says what was done per stream, with counts and row ranges in the input's
numbering (file lines, header = line 1; Parquet: row index + 2), and how many findings
``logs check`` still reports (warnings only, or none).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from fieldlogs.quality.checks import check_run
from fieldlogs.quality.tacho import cumulative_again
from fieldlogs.runs.handle import Run
from fieldlogs.runs.typed import LogFormat
from fieldlogs.runs.write import check_output_folder, write_run
from schemas.enums import Severity
from schemas.errors import FindingsError, RefusedError
from schemas.findings import Finding, count_by_severity
from schemas.frames import FIRST_DATA_LINE

REPAIR_LOG = "repair_log.json"
#: Row ranges listed per action in the log (the count is always complete).
MAX_RANGES = 100


@dataclass
class RepairAction:
    action: str
    """sort_by_t, sort_by_key, drop_duplicate_rows, drop_duplicate_t, drop_duplicate_key or
    bridge_pulse_reset."""
    count: int
    """Rows affected (sorted: rows found out of order; resets: resets bridged)."""
    rows: list[list[int]]
    """[first, last] input row ranges (at most MAX_RANGES)."""
    message: str

    def to_dict(self) -> dict[str, Any]:
        return {"action": self.action, "count": self.count, "rows": self.rows, "message": self.message}


@dataclass
class StreamRepair:
    stream: str
    file: str
    rows_in: int
    rows_out: int
    actions: list[RepairAction] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "stream": self.stream,
            "file": self.file,
            "rows_in": self.rows_in,
            "rows_out": self.rows_out,
            "actions": [a.to_dict() for a in self.actions],
        }


@dataclass
class RepairResult:
    source: str
    out: str
    format: str
    streams: list[StreamRepair]
    remaining: list[Finding] = field(default_factory=list)
    """What ``logs check`` still finds in the output."""

    @property
    def changed(self) -> bool:
        return any(s.actions for s in self.streams)

    def to_dict(self) -> dict[str, Any]:
        by_rule: dict[str, int] = {}
        for f in self.remaining:
            by_rule[f.rule] = by_rule.get(f.rule, 0) + 1
        counts = count_by_severity(self.remaining)
        return {
            "source": self.source,
            "out": self.out,
            "format": self.format,
            "rows": "input row numbers: file lines (header = line 1); Parquet: row index + 2",
            "streams": [s.to_dict() for s in self.streams],
            "remaining": {"errors": counts["error"], "warnings": counts["warning"], "by_rule": by_rule},
        }


def _ranges(lines: np.ndarray) -> list[list[int]]:
    lines = np.sort(np.asarray(lines, dtype=np.int64))
    if len(lines) == 0:
        return []
    breaks = np.flatnonzero(np.diff(lines) != 1)
    starts = np.concatenate(([0], breaks + 1))[:MAX_RANGES]
    ends = np.concatenate((breaks, [len(lines) - 1]))[:MAX_RANGES]
    return [[int(lines[s]), int(lines[e])] for s, e in zip(starts, ends, strict=True)]


def _line_list(lines: list[list[int]], total: int) -> str:
    txt = ", ".join(str(a) if a == b else f"{a}–{b}" for a, b in lines[:5])
    shown = sum(b - a + 1 for a, b in lines[:5])
    return txt + (" …" if shown < total else "")


#: Streams with many rows per t: sorted by their key, duplicates judged on the key.
KEYED_STREAMS = {
    "gnss_obs": ["t", "receiver", "sat", "signal"],
    "gnss_nav": ["sat", "toc_gps_s"],
    "gnss_sbas": ["t", "prn"],
}


def _repair_keyed(name: str, frame: pd.DataFrame, file: str) -> tuple[pd.DataFrame, StreamRepair]:
    """gnss_obs / gnss_nav / gnss_sbas: sort by the key, drop exact duplicates, then (gnss_obs) rows
    repeating a key (receiver, t, sat, signal), keeping the first in file order."""
    rep = StreamRepair(name, file, len(frame), len(frame))
    key = KEYED_STREAMS[name]
    f = frame.reset_index(drop=True)
    order = np.lexsort(
        [
            f[k].astype("string").fillna("").to_numpy(dtype=object) if f[k].dtype != "float64" else f[k].to_numpy()
            for k in reversed(key)
        ]
    )
    moved = np.flatnonzero(order != np.arange(len(f)))
    if len(moved):
        f = f.iloc[order]
        rows = _ranges(moved + FIRST_DATA_LINE)
        rep.actions.append(
            RepairAction("sort_by_key", len(moved), rows, f"sorted by ({', '.join(key)}): {len(moved)} row(s) moved")
        )
    for action, mask, what in (
        ("drop_duplicate_rows", f.duplicated(keep="first"), "repeating an earlier row exactly"),
        ("drop_duplicate_key", None, f"repeating the key ({', '.join(key)}) of an earlier row"),
    ):
        if mask is None:
            if name != "gnss_obs":
                continue
            mask = f.duplicated(subset=key, keep="first")
        dropped = f.index[mask.to_numpy()].to_numpy()
        if len(dropped):
            f = f[~mask.to_numpy()]
            rows = _ranges(dropped + FIRST_DATA_LINE)
            rep.actions.append(
                RepairAction(
                    action,
                    len(dropped),
                    rows,
                    f"dropped {len(dropped)} row(s) {what} (lines {_line_list(rows, len(dropped))})",
                )
            )
    rep.rows_out = len(f)
    return f.reset_index(drop=True), rep


def repair_stream(name: str, frame: pd.DataFrame, file: str) -> tuple[pd.DataFrame, StreamRepair]:
    """The repaired frame (fresh 0-based index) and what was done. ``frame`` is not modified."""
    if name in KEYED_STREAMS:
        return _repair_keyed(name, frame, file)
    rep = StreamRepair(name, file, len(frame), len(frame))
    f = frame.reset_index(drop=True)  # label = input row index; input line = label + 2
    t = f["t"].to_numpy(dtype=float, na_value=np.nan)
    back = np.flatnonzero(np.diff(t) < 0) + 1
    if len(back):
        f = f.iloc[np.argsort(t, kind="stable")]
        rows = _ranges(back + FIRST_DATA_LINE)
        rep.actions.append(
            RepairAction(
                "sort_by_t",
                len(back),
                rows,
                f"sorted by t: {len(back)} row(s) were earlier than the row before "
                f"(lines {_line_list(rows, len(back))})",
            )
        )
    ts = f["t"].to_numpy(dtype=float)
    eq = ts[1:] == ts[:-1]
    if eq.any():
        every = np.concatenate(([False], eq)) | np.concatenate((eq, [False]))
        sub = f[every]
        exact = sub.index[sub.duplicated(keep="first").to_numpy()].to_numpy()
        if len(exact):
            f = f.drop(index=pd.Index(exact))
            rows = _ranges(exact + FIRST_DATA_LINE)
            rep.actions.append(
                RepairAction(
                    "drop_duplicate_rows",
                    len(exact),
                    rows,
                    f"dropped {len(exact)} row(s) repeating an earlier row exactly "
                    f"(lines {_line_list(rows, len(exact))})",
                )
            )
        ts = f["t"].to_numpy(dtype=float)
        later = np.concatenate(([False], ts[1:] == ts[:-1]))
        if later.any():
            dropped = f.index[later].to_numpy()
            f = f[~later]
            rows = _ranges(dropped + FIRST_DATA_LINE)
            rep.actions.append(
                RepairAction(
                    "drop_duplicate_t",
                    len(dropped),
                    rows,
                    f"dropped {len(dropped)} row(s) whose t repeats an earlier row's with other values, "
                    f"keeping the first row of each t in file order (lines {_line_list(rows, len(dropped))})",
                )
            )
    if name == "tacho":
        f = _bridge_resets(f, rep)
    rep.rows_out = len(f)
    return f.reset_index(drop=True), rep


def _bridge_resets(f: pd.DataFrame, rep: StreamRepair) -> pd.DataFrame:
    s = f["pulses"]
    nn = s.notna().to_numpy()
    p = s.to_numpy(dtype=np.int64, na_value=0)[nn]
    if len(p) < 2:
        return f
    fixed, resets = cumulative_again(p)
    if not len(resets):
        return f
    labels = f.index.to_numpy()[nn]
    lines = labels[resets] + FIRST_DATA_LINE
    offsets = np.cumsum(p[resets - 1])
    f = f.copy()
    new = s.to_numpy(dtype=np.int64, na_value=0).copy()
    new[nn] = fixed
    f["pulses"] = pd.arrays.IntegerArray(new, ~nn)
    details = "; ".join(
        f"line {int(ln)}: {int(p[r - 1])} → {int(p[r])}, later rows +{int(o)}"
        for ln, r, o in zip(lines[:5], resets[:5], offsets[:5], strict=True)
    )
    rep.actions.append(
        RepairAction(
            "bridge_pulse_reset",
            len(resets),
            _ranges(lines),
            f"bridged {len(resets)} pulse-counter reset(s), pulses cumulative again ({details}"
            + (" …)" if len(resets) > 5 else ")"),
        )
    )
    return f


def _refusals(run: Run) -> list[Finding]:
    """Problems a safe repair cannot fix (loads every stream)."""
    frames = {n: run.stream(n) for n in run.streams_present()}
    bad = [f for f in run.findings if f.severity == Severity.ERROR and f.rule != "schema.unknown_column"]
    for name, frame in frames.items():
        if frame is not None and "t" in frame.columns and frame["t"].isna().any():
            rows = np.flatnonzero(frame["t"].isna().to_numpy())
            bad.append(
                Finding(
                    "log.null_t",
                    Severity.ERROR,
                    name,
                    f"{len(rows)} row(s) without t cannot be placed in time",
                    file=str(run.stream_file(name)),
                    row=int(rows[0]) + FIRST_DATA_LINE,
                    column="t",
                    value=len(rows),
                )
            )
    return bad


def repair_run(
    src: Path | str, out: Path | str, *, force: bool = False, fmt: LogFormat | None = None, strict: bool = False
) -> RepairResult:
    """Repair ``src`` into the new folder ``out``; the input is never written to.

    Raises RefusedError (output exists, is the input, inside it or containing it),
    FindingsError (the run has problems only a person can fix, before or after the safe
    repairs — after: the findings of ``logs check`` on the repaired run, warnings too with
    ``strict``; nothing written), InputError (unreadable).
    """
    src, out = Path(src), Path(out)
    check_output_folder(src, out)
    run = Run(src)
    if out.exists() and not force:
        raise RefusedError("output folder exists; use --force to replace it", path=out)
    refused = _refusals(run)
    if run.meta is None or refused:
        raise FindingsError(
            f"{len(refused)} problem(s) cannot be repaired safely (fix them by hand first); nothing was written",
            refused,
            path=src,
        )
    formats = {run.stream_format(n) for n in run.streams_present()}
    out_fmt: LogFormat = fmt or (formats.pop() if len(formats) == 1 else "parquet")  # type: ignore[assignment]
    streams: dict[str, pd.DataFrame] = {}
    reports: list[StreamRepair] = []
    for name in run.streams_present():
        frame = run.stream(name)
        assert frame is not None  # refused above otherwise
        fixed, rep = repair_stream(name, frame, str(run.stream_file(name)))
        streams[name] = fixed
        reports.append(rep)
    result = RepairResult(str(src), str(out), out_fmt, reports)

    def check_repaired(tmp: Path) -> None:
        """``logs check`` of the repaired run, in its temporary folder: refused when
        problems remain, else the log with what is still found."""
        result.remaining = [_relocated(f, tmp, out) for f in check_run(tmp)]
        left = [f for f in result.remaining if f.severity == Severity.ERROR or strict]
        if left:
            raise FindingsError(
                f"{len(left)} problem(s) remain after the safe repairs (logs check of the repaired run); "
                "they need a person: nothing was written",
                left,
                path=src,
            )
        (tmp / REPAIR_LOG).write_text(json.dumps(result.to_dict(), indent=2, ensure_ascii=False) + "\n", "utf-8")

    write_run(out, run.meta, streams, fmt=out_fmt, force=force, inputs=[src], before_publish=check_repaired)
    return result


def _relocated(f: Finding, tmp: Path, out: Path) -> Finding:
    """A finding on the temporary folder as one on the output folder it was to become."""
    if f.file and Path(f.file).is_relative_to(tmp):
        f.file = str(out / Path(f.file).relative_to(tmp))
    return f
