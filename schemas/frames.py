"""Typed frames from raw text cells, and declarative checks (pandera) → findings.

Used for every source file, log stream and plan: read everything as text, coerce each
column to its declared type (a cell that does not parse is a finding naming row and
column), then let pandera check nullability, enumerations, ranges and keys lazily so that
*every* problem is collected.

Findings (one per cell or row, capped per check):

* ``schema.missing_column`` (error) — a required column is not in the header. Fix: add the
  column (its name exactly as the table declares it).
* ``schema.unknown_column`` (warning) — a column the table does not declare (a typo of a
  known name is named in the message); it is ignored. Fix: rename it to the declared name, or
  delete it.
* ``schema.type`` (error) — a cell is not a valid value of its column's type (number, integer,
  km, date …). Fix: correct the cell (decimal point, not comma; no units in the cell).
* ``schema.null`` (error) — a required cell is empty. Fix: fill it.
* ``schema.enum`` (error) — a cell holds a value not among the column's allowed values. Fix:
  use one of the values the message lists.
* ``schema.range`` (error) — a value outside its column's declared range (lat/lon off the
  globe, a negative length …). Fix: correct the value.
* ``schema.duplicate_key`` (error) — two rows with the same key (e.g. one km twice on one
  line/track). Fix: delete the duplicate row, or correct its key columns.
* ``schema.check`` (error) — a row fails another declared check of its table. Fix: correct
  the row as the message says.
"""

from __future__ import annotations

import difflib
import re
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
import pyarrow as pa_arrow
import pyarrow.compute as pc

from schemas.enums import Severity
from schemas.findings import Finding
from schemas.frame_screen import passes_checks
from schemas.model import Column, Table
from schemas.text_cells import BLANK_WORDS as BLANK_WORDS
from schemas.text_cells import stripped_text
from schemas.units import parse_km_array

if TYPE_CHECKING:
    import pandera.pandas as pa

#: Line number of the first data row in a file with one header line.
FIRST_DATA_LINE = 2
#: Pandas dtype each declared dtype is coerced to.
PANDAS_DTYPE = {"str": "string", "int": "Int64", "float": "float64", "bool": "boolean"}
#: Whole numbers are stored as int64: a value at or beyond 2**63 in magnitude does not fit.
INT64_LIMIT = 2.0**63


@dataclass
class Coerced:
    frame: pd.DataFrame
    findings: list[Finding]
    missing: list[str]
    """Declared columns absent from the input (added as nulls, not checked)."""


def suggest(name: str, candidates: list[str]) -> str | None:
    """Closest known name to a misspelled one, or None."""
    match = difflib.get_close_matches(name, candidates, n=1, cutoff=0.6)
    return match[0] if match else None


def _row_keys(table: Table, frame: pd.DataFrame, idx: int) -> dict[str, object]:
    keys: dict[str, object] = {}
    for k in table.primary_key:
        if k in frame.columns:
            v = frame[k].iat[idx]
            keys[k] = None if v is pd.NA or (isinstance(v, float) and np.isnan(v)) else v
    return keys


def coerce_frame(
    table: Table,
    raw: pd.DataFrame,
    *,
    file: str | None = None,
    allow_extra: bool = False,
    first_line: int = FIRST_DATA_LINE,
) -> Coerced:
    """Coerce a frame of text (or already typed) cells to the declared column types.

    Missing required columns and cells that do not parse become findings; absent optional
    columns are added as nulls; columns are returned in declared order (extras dropped
    unless ``allow_extra``). The returned frame keeps the raw positional index so that
    ``index + first_line`` is the file line of a row.
    """
    known = table.column_names
    typed = _already_typed(table, raw)
    if typed is not None:
        return Coerced(typed, [], [c for c in known if c not in raw.columns])
    raw = raw.reset_index(drop=True)
    raw.columns = [str(c).strip() for c in raw.columns]
    extras = [c for c in raw.columns if c not in known]
    findings = _missing_columns(table, raw, extras, file)
    if not allow_extra:
        findings += _unknown_columns(table, extras, file)
    out: dict[str, pd.Series] = {}
    for col in table.columns:
        if col.name in raw.columns:
            values, bad = _coerce_column(col, raw[col.name])
            findings += _bad_cells(table, col, raw[col.name], bad, file, first_line)
            out[col.name] = values
        else:
            out[col.name] = pd.Series([None] * len(raw), index=raw.index, dtype=PANDAS_DTYPE[col.dtype])
    if allow_extra:
        for c in extras:
            out[c] = raw[c]
    missing = [c for c in known if c not in raw.columns]
    # one DataFrame from all columns at once (column-by-column insertion is slow)
    return Coerced(pd.DataFrame(out, index=raw.index), findings, missing)


def _already_typed(table: Table, raw: pd.DataFrame) -> pd.DataFrame | None:
    """The frame :func:`coerce_frame` returns, built without its per-column machinery when
    nothing in ``raw`` can give a finding: every column a declared one, none repeated, every
    required one present, number columns already float64 (as :mod:`dbtools.typed_csv`
    parses them) with no infinity, whole numbers integral and within int64, text columns
    Arrow strings (stripped and blanked by the same Arrow kernels pandas's string methods
    call in :func:`_blank` and :func:`_coerce_column`), flag columns of 0/1 words only
    (:func:`_flags`). None otherwise:
    the general path names every problem. Same values, dtypes, index and column order
    (hypothesis tests in tests/dbtools/test_typed_csv.py); it costs ≈ 0.1 ms where the
    general path costs ≈ 1 ms a column, which is most of the reading of a small stream."""
    names = [str(c) for c in raw.columns]
    declared = {c.name: c for c in table.columns}
    if len(set(names)) != len(names) or any(n not in declared for n in names):
        return None
    if any(c.required and c.name not in names for c in table.columns):
        return None
    n = len(raw)
    out: dict[str, object] = {}
    for col in table.columns:
        values = _typed_column(col, raw[col.name]) if col.name in names else _null_column(col, n)
        if values is None:
            return None
        out[col.name] = values
    return pd.DataFrame(out, index=pd.RangeIndex(n), copy=False)


def _typed_column(col: Column, s: pd.Series) -> object | None:
    """One present column for :func:`_already_typed` (None: the general path decides)."""
    if col.dtype in ("float", "int"):
        if s.dtype != np.float64:
            return None
        values = s.to_numpy()
        if np.isinf(values).any():
            return None
        if col.dtype == "float":
            return values
        nan = np.isnan(values)
        whole = values[~nan]
        if (np.floor(whole) != whole).any() or (np.abs(whole) >= INT64_LIMIT).any():
            return None
        ints = np.zeros(len(values), dtype=np.int64)
        ints[~nan] = whole
        return pd.arrays.IntegerArray(ints, nan)
    if col.dtype not in ("str", "bool") or not isinstance(s.array, pd.arrays.ArrowStringArray):
        return None
    text = stripped_text(pa_arrow.chunked_array(pa_arrow.array(s.array)))
    return pd.arrays.ArrowStringArray(text) if col.dtype == "str" else _flags(text)


def _flags(text: pa_arrow.ChunkedArray) -> pd.arrays.BooleanArray | None:
    """A flag column's stripped text (blanks null) as :func:`_coerce_column` types it — lower
    case in ``_TRUE`` true, in ``_FALSE`` false, blank missing — or None when a cell is
    neither (a bad cell: the general path names it)."""
    lower = pc.utf8_lower(text)
    true = pc.is_in(lower, value_set=pa_arrow.array(sorted(_TRUE))).to_numpy(zero_copy_only=False)
    false = pc.is_in(lower, value_set=pa_arrow.array(sorted(_FALSE))).to_numpy(zero_copy_only=False)
    missing = text.is_null().to_numpy(zero_copy_only=False)
    if not (true | false | missing).all():
        return None
    return pd.arrays.BooleanArray(np.asarray(true, dtype=bool), np.asarray(missing, dtype=bool))


def _null_column(col: Column, n: int) -> object:
    """An absent optional column as :func:`coerce_frame` adds it (all null)."""
    if col.dtype == "float":
        return np.full(n, np.nan)
    if col.dtype == "int":
        return pd.arrays.IntegerArray(np.zeros(n, dtype=np.int64), np.ones(n, dtype=bool))
    return pd.Series([None] * n, dtype=PANDAS_DTYPE[col.dtype]).array


def _missing_columns(table: Table, raw: pd.DataFrame, extras: list[str], file: str | None) -> list[Finding]:
    findings = []
    for col in table.columns:
        if col.name in raw.columns or not col.required:
            continue
        hint = suggest(col.name, extras)
        msg = f"required column '{col.name}' is missing"
        if hint:
            msg += f" (found '{hint}': misspelled?)"
        findings.append(
            Finding(
                "schema.missing_column",
                Severity.ERROR,
                table.name,
                msg,
                file=file,
                column=col.name,
                value=hint,
                limit=col.name,
            )
        )
    return findings


def _unknown_columns(table: Table, extras: list[str], file: str | None) -> list[Finding]:
    findings = []
    for c in extras:
        hint = suggest(c, table.column_names)
        msg = f"unknown column '{c}' ignored" + (f" (did you mean '{hint}'?)" if hint else "")
        findings.append(
            Finding(
                "schema.unknown_column", Severity.WARNING, table.name, msg, file=file, column=c, value=c, limit=hint
            )
        )
    return findings


#: Cells named one by one per column; beyond, one finding counts the rest.
MAX_CELL_FINDINGS = 1000


def _bad_cells(
    table: Table, col: Column, cells: pd.Series, bad: np.ndarray, file: str | None, first_line: int
) -> list[Finding]:
    findings = []
    for i in np.flatnonzero(bad)[:MAX_CELL_FINDINGS]:
        cell = cells.iat[i]
        findings.append(
            Finding(
                "schema.type",
                Severity.ERROR,
                table.name,
                f"'{cell}' is not a valid {_type_word(col)}",
                file=file,
                row=int(i) + first_line if file else None,
                column=col.name,
                value=str(cell),
                limit=_type_word(col),
            )
        )
    n_bad = int(bad.sum())
    if n_bad > MAX_CELL_FINDINGS:
        findings.append(
            Finding(
                "schema.type",
                Severity.ERROR,
                table.name,
                f"{n_bad - MAX_CELL_FINDINGS} more cells are not a valid {_type_word(col)}",
                file=file,
                column=col.name,
                value=n_bad,
                limit=0,
            )
        )
    return findings


def _type_word(col: Column) -> str:
    if col.km_notation:
        return "kilometrage (metres or 12k345.6)"
    return {"str": "text", "int": "whole number", "float": "number", "bool": "0/1 flag"}[col.dtype]


_TRUE = {"1", "true", "yes", "y", "t"}
_FALSE = {"0", "false", "no", "n", "f"}


def _blank(s: pd.Series) -> np.ndarray:
    if s.dtype == object or pd.api.types.is_string_dtype(s.dtype):
        txt = s.astype("string").str.strip()
        return (txt.isna() | (txt == "") | txt.str.lower().isin(["nan", "na", "null"])).to_numpy(
            dtype=bool, na_value=True
        )
    return s.isna().to_numpy()


def _fast_float(s: pd.Series, blank: np.ndarray) -> pd.Series | None:
    """Text → float64 through pyarrow's (correctly rounded) parser when *every* non-blank
    cell is a plain number; None otherwise, and the caller takes the general path."""
    if not pd.api.types.is_string_dtype(s.dtype) or s.dtype == object:
        return None
    try:
        arr = pa_arrow.array(s.str.strip().mask(pd.Series(blank, index=s.index)))
        out = pc.cast(arr, pa_arrow.float64())
    except (pa_arrow.ArrowInvalid, pa_arrow.ArrowNotImplementedError, pa_arrow.ArrowTypeError):
        return None
    vals = out.to_numpy(zero_copy_only=False).astype(np.float64)
    if (np.isnan(vals) & ~blank).any():  # e.g. "-nan": let the general path call it a bad cell
        return None
    return pd.Series(vals, index=s.index, dtype="float64")


def _coerce_column(col: Column, s: pd.Series) -> tuple[pd.Series, np.ndarray]:
    """Return (typed series, mask of cells that are not blank but do not parse)."""
    blank = _blank(s)
    if col.dtype == "str":
        if pd.api.types.is_float_dtype(s.dtype):
            # e.g. codes read from Excel as numbers: 1.0 → "1"
            txt = s.map(lambda v: f"{v:g}" if pd.notna(v) else pd.NA).astype("string")
        else:
            txt = s.astype("string").str.strip()
        txt = txt.mask(pd.Series(blank, index=s.index))
        return txt, np.zeros(len(s), dtype=bool)
    if col.dtype == "float":
        fast = _fast_float(s, blank)
        if fast is not None:
            vals = fast
            bad = np.zeros(len(s), dtype=bool)
        elif pd.api.types.is_numeric_dtype(s.dtype) and not pd.api.types.is_bool_dtype(s.dtype):
            vals = s.astype("float64")
            bad = np.zeros(len(s), dtype=bool)
        elif col.km_notation:
            arr, ok = parse_km_array(s.to_numpy(dtype=object))
            vals = pd.Series(arr, index=s.index)
            bad = ~ok & ~blank
        else:
            vals = pd.to_numeric(s.astype("string").str.strip(), errors="coerce").astype("float64")
            bad = vals.isna().to_numpy() & ~blank
        inf = np.isinf(vals.to_numpy(dtype=float, na_value=np.nan))
        bad |= inf
        vals = vals.where(~inf)
        return vals, bad
    if col.dtype == "int":
        fast = _fast_float(s, blank)
        num = (
            fast
            if fast is not None
            else pd.to_numeric(
                s.astype("string").str.strip() if not pd.api.types.is_numeric_dtype(s.dtype) else s, errors="coerce"
            )
        )
        return _whole_numbers(num.to_numpy(dtype=float, na_value=np.nan), blank, s.index)
    # bool
    txt = s.astype("string").str.strip().str.lower()
    vals = pd.Series(pd.NA, index=s.index, dtype="boolean")
    vals[txt.isin(_TRUE).fillna(False).to_numpy(dtype=bool)] = True
    vals[txt.isin(_FALSE).fillna(False).to_numpy(dtype=bool)] = False
    bad = vals.isna().to_numpy() & ~blank
    return vals, bad


def _whole_numbers(arr: np.ndarray, blank: np.ndarray, index: pd.Index) -> tuple[pd.Series, np.ndarray]:
    """Parsed numbers of a whole-number column → (Int64 series, mask of bad cells): the
    one typed path every integer column takes. A cell that is not blank and is not a
    finite whole number within int64 (``inf``, ``1e400``, ``1e308``, ``2.5``, text) is
    bad and read as null, never cast (a cast of ``inf`` or ``1e308`` raises)."""
    known = ~np.isnan(arr)
    with np.errstate(invalid="ignore"):
        ok = known & np.isfinite(arr) & (np.abs(arr) < INT64_LIMIT) & (np.floor(arr) == arr)
    bad = (known & ~ok) | (~known & ~blank)
    ints = np.zeros(len(arr), dtype=np.int64)
    ints[ok] = arr[ok]
    return pd.Series(pd.arrays.IntegerArray(ints, ~ok), index=index), bad


def pandera_schema(table: Table, *, check_keys: bool = True, present: list[str] | None = None) -> pa.DataFrameSchema:
    """The pandera schema of a declared table (types already coerced), limited to ``present``
    (pandera imported here: reading typed frames does not need it)."""
    import pandera.pandas as pa

    cols: dict[str, pa.Column] = {}
    names = set(table.column_names if present is None else present)
    for c in table.columns:
        if c.name not in names:
            continue
        checks: list[pa.Check] = []
        if c.enum is not None:
            checks.append(pa.Check.isin(list(c.enum)))
        if c.min is not None and c.max is not None:
            checks.append(pa.Check.in_range(c.min, c.max))
        elif c.min is not None:
            checks.append(pa.Check.ge(c.min))
        elif c.max is not None:
            checks.append(pa.Check.le(c.max))
        cols[c.name] = pa.Column(nullable=c.nullable, checks=checks, required=False, coerce=False)
    pk_ok = table.primary_key and all(k in names for k in table.primary_key)
    unique = list(table.primary_key) if check_keys and pk_ok else None
    return pa.DataFrameSchema(cols, unique=unique, report_duplicates="all" if unique else "exclude_first")


_RANGE_RE = re.compile(r"in_range\(([^,]+), ([^)]+)\)|greater_than_or_equal_to\((.+)\)|less_than_or_equal_to\((.+)\)")


def check_frame(
    table: Table,
    frame: pd.DataFrame,
    *,
    file: str | None = None,
    first_line: int = FIRST_DATA_LINE,
    check_keys: bool = True,
    max_per_check: int = 1000,
) -> list[Finding]:
    """Run the declared checks; every failing cell is a finding (capped per check). A frame
    that :func:`schemas.frame_screen.passes_checks` clears has none, and pandera is not run."""
    if passes_checks(table, frame, check_keys=check_keys):
        return []  # proven clean without pandera (schemas.frame_screen)
    from pandera.errors import SchemaErrors

    schema = pandera_schema(table, check_keys=check_keys, present=list(frame.columns))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            schema.validate(frame, lazy=True)
            return []
        except SchemaErrors as exc:
            cases = exc.failure_cases
    findings: list[Finding] = []
    dup_rows: set[int | None] = set()
    for (column, check), group in cases.groupby(["column", "check"], sort=False, dropna=False):
        check = str(check)
        shown = group.head(max_per_check)
        for _, case in shown.iterrows():
            if _rule_for(check) == "range" and _infinite(case["failure_case"]):
                continue  # one finding per problem: infinity is ``schema.not_finite`` (DBs) or ``schema.type`` (files)
            idx = case["index"]
            idx = int(idx) if idx is not None and not pd.isna(idx) else None
            if _rule_for(check) == "duplicate_key":
                if idx in dup_rows:
                    continue  # one finding per duplicated row, not one per key column
                dup_rows.add(idx)
                column = "nan"
            findings.append(_finding_for(table, frame, str(column), check, case["failure_case"], idx, file, first_line))
        if len(group) > max_per_check:
            findings.append(
                Finding(
                    f"schema.{_rule_for(check)}",
                    Severity.ERROR,
                    table.name,
                    f"{len(group) - max_per_check} more rows fail the same check ({check})",
                    file=file,
                    column=str(column),
                    value=len(group),
                    limit=0,
                )
            )
    return findings


def _infinite(value: object) -> bool:
    """True for a float ±inf (a pandera failure case)."""
    return isinstance(value, float | np.floating) and bool(np.isinf(value))


def _rule_for(check: str) -> str:
    if check == "not_nullable":
        return "null"
    if check.startswith("isin"):
        return "enum"
    if "range" in check or "than" in check:
        return "range"
    if "uniqueness" in check or check == "unique" or "duplicate" in check:
        return "duplicate_key"
    return "check"


def _finding_for(
    table: Table,
    frame: pd.DataFrame,
    column: str,
    check: str,
    value: object,
    idx: int | None,
    file: str | None,
    first_line: int,
) -> Finding:
    rule = _rule_for(check)
    keys = _row_keys(table, frame, idx) if idx is not None and idx < len(frame) else {}
    row = idx + first_line if (idx is not None and file) else None
    limit: object = None
    if rule == "null":
        msg = "empty value where one is required"
    elif rule == "enum":
        col = table.column(column)
        limit = list(col.enum or ())
        hint = suggest(str(value), limit) if value is not None else None
        msg = f"'{value}' is not one of {', '.join(limit)}" + (f" (did you mean '{hint}'?)" if hint else "")
    elif rule == "range":
        col = table.column(column)
        limit = [col.min, col.max]
        lo = "−∞" if col.min is None else f"{col.min:g}"
        hi = "+∞" if col.max is None else f"{col.max:g}"
        msg = f"{value} {col.unit} is outside [{lo}, {hi}]".replace("  ", " ")
    elif rule == "duplicate_key":
        limit = list(table.primary_key)
        msg = f"duplicate key ({', '.join(table.primary_key)}) — each must be unique"
        column = ",".join(table.primary_key) if column in ("nan", "None") else column
    else:
        msg = f"fails check {check}: {value}"
    return Finding(
        f"schema.{rule}",
        Severity.ERROR,
        table.name,
        msg,
        keys=keys,
        value=value,
        limit=limit,
        file=file,
        row=row,
        column=None if column in ("nan", "None") else column,
    )


def read_and_check(table: Table, raw: pd.DataFrame, *, file: str | None = None, allow_extra: bool = False) -> Coerced:
    """Coerce then check: the frame plus all findings (type, null, enum, range, keys)."""
    co = coerce_frame(table, raw, file=file, allow_extra=allow_extra)
    bad_rows: set[int] = {f.row - FIRST_DATA_LINE for f in co.findings if f.rule == "schema.type" and f.row}
    frame = co.frame
    checked = frame if not bad_rows else frame.drop(index=list(bad_rows))
    present = [c for c in table.column_names if c not in co.missing]
    co.findings.extend(check_frame(table, checked[present], file=file))
    return co
