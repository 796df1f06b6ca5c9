"""Reading a source set (SPEC §3 "Source files") into a :class:`Network` plus findings.

An optional ``network.toml`` declares the operating area, metric CRS and height datum
(:func:`dbtools.gis.georef.read_declaration`); its entries go to ``Network.meta``. Its
``[csv]`` table declares the convention of the CSV files (``delimiter = ";"``,
``decimal = ","``: :func:`declared_locale`), for source sets saved from a spreadsheet in a
European locale; without it the convention is detected (:mod:`dbtools.csv_locale`), and
the options of ``db build`` / ``db validate`` come before it.

Findings:

* ``source.missing_file`` (error) — a required source file (``NAME.csv`` or ``.xlsx``) is not
  in the source set folder. Fix: add the file (a header line is enough for an empty table),
  or point the command at the right folder.
* ``source.unknown_line`` (error) — a ``line_code`` is used in a table but not listed in
  ``lines``. Fix: add the line to ``lines.csv``, or correct the code.
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.csv_locale import CsvLocale, csv_table, head_dialect
from dbtools.gis.georef import NETWORK_FILE, read_declaration, write_declaration
from dbtools.network import Network, canonical_with_index, empty_frame
from dbtools.rules.area import check_area
from dbtools.rules.common import Locator
from dbtools.rules.schema import check_empty_tables
from dbtools.tabular import code_columns, find_table_file, read_table_file, sha256_file, text_columns
from dbtools.typed_csv import Notation, read_csv_typed
from schemas.enums import Severity, Track
from schemas.errors import InputError
from schemas.findings import Finding
from schemas.frames import FIRST_DATA_LINE, read_and_check
from schemas.model import Table
from schemas.tables import FEATURE_POINTS, LINES, SOURCE_TABLES, TRACK_FEATURE_POINTS


def read_source_set(folder: Path, locale: CsvLocale | None = None) -> tuple[Network, list[Finding]]:
    """Read every source file of a folder; returns the network and all findings.

    Rows with errors stay in the frames (so later checks can still run); callers decide
    whether errors block them. ``locale``: the CSV convention declared by the caller's
    options, over the folder's ``network.toml [csv]`` (:func:`declared_locale`).
    """
    folder = Path(folder)
    if not folder.exists():
        raise InputError("no such folder", path=folder)
    if not folder.is_dir():
        raise InputError("not a folder (expected a source set with gis, balises, feature_points)", path=folder)
    findings: list[Finding] = []
    locale = (locale or CsvLocale()).over(declared_locale(folder))
    tables: dict[str, pd.DataFrame] = {}
    files: dict[str, str] = {}
    hashes: dict[str, str] = {}
    for name, table in SOURCE_TABLES.items():
        path = find_table_file(folder, name)
        if path is None:
            if table.required:
                findings.append(
                    Finding(
                        "source.missing_file",
                        Severity.ERROR,
                        name,
                        f"required source file {name}.csv (or .xlsx) is missing",
                        file=str(folder / f"{name}.csv"),
                    )
                )
            tables[name] = empty_frame(table)
            continue
        raw = _read_typed(table, path, locale, findings)  # None: as text
        if raw is None:
            tf = read_table_file(
                path,
                table=name,
                sheet=name,
                code_columns=code_columns(table),
                text_columns=text_columns(table),
                locale=locale,
                numeric_columns=_numbers(table),
            )
            raw = tf.frame
            findings.extend(tf.findings)
        files[name] = str(path)
        hashes[path.name] = sha256_file(path)
        co = read_and_check(table, raw, file=str(path), allow_extra=(name == LINES.name))
        findings.extend(co.findings)
        frame = co.frame
        if name == LINES.name:
            frame = _lines_attributes(frame, table.column_names)
        tables[name] = frame
    tables[FEATURE_POINTS.name] = _with_seq(tables[FEATURE_POINTS.name])
    tables[TRACK_FEATURE_POINTS.name] = _with_seq(tables[TRACK_FEATURE_POINTS.name])
    findings.extend(_line_codes(tables, files))
    net = Network({}, origin=str(folder), files=files)
    for name, frame in tables.items():
        # frames still carry the positional index of their file rows: keep it as line numbers
        net.tables[name], labels = canonical_with_index(SOURCE_TABLES[name], frame)
        if name in files:
            net.source_rows[name] = np.asarray(labels, dtype=np.int64) + FIRST_DATA_LINE
    net.meta = _declared_meta(folder, hashes)
    loc = Locator(files, net.source_rows)
    findings.extend(check_empty_tables(net.tables, loc, tables_read=set(files)))
    findings.extend(check_area(net, loc))
    return net, findings


def declared_locale(folder: Path) -> CsvLocale:
    """The ``[csv]`` table of the folder's ``network.toml`` (``delimiter``: ``,``, ``;``,
    ``tab`` or ``|``; ``decimal``: ``.`` or ``,``); nothing declared without one. InputError
    naming the file on an unknown key or value."""
    path = Path(folder) / NETWORK_FILE
    if not path.is_file():
        return CsvLocale()
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8-sig")).get("csv", {})
    except (UnicodeDecodeError, tomllib.TOMLDecodeError):
        return CsvLocale()  # read_declaration names the problem
    return csv_table(table, path)


def _read_typed(table: Table, path: Path, locale: CsvLocale, findings: list[Finding]) -> pd.DataFrame | None:
    """A ``.csv`` read by the typed reader in the notation its head settles
    (:func:`dbtools.csv_locale.head_dialect`; the convention's finding added), or None for
    the text path (a workbook, a file the head cannot settle or the typed reader declines)."""
    if path.suffix.lower() != ".csv":
        return None
    dialect = head_dialect(path, _numbers(table), locale)
    if dialect is None:
        return None
    raw = read_csv_typed(table, path, Notation(dialect.delimiter, dialect.decimal))
    note = dialect.finding(path, table.name) if raw is not None else None
    findings += [note] if note is not None else []
    return raw


def _numbers(table: Table) -> list[str]:
    return [c.name for c in table.columns if c.dtype in ("float", "int")]


def _declared_meta(folder: Path, hashes: dict[str, str]) -> dict[str, str]:
    """Source hashes (``network.toml`` included) and what ``network.toml`` declares."""
    declared = folder / NETWORK_FILE
    if declared.is_file():
        hashes[declared.name] = sha256_file(declared)
    meta = {f"source_sha256:{k}": v for k, v in sorted(hashes.items())}
    if declared.is_file():
        meta.update(read_declaration(declared))
    return meta


def _lines_attributes(frame: pd.DataFrame, known: list[str]) -> pd.DataFrame:
    extras = [c for c in frame.columns if c not in known]
    if extras:
        frame = frame.copy()
        frame["attributes_json"] = [
            json.dumps({k: v for k, v in zip(extras, row, strict=True) if str(v).strip()}, ensure_ascii=False)
            for row in frame[extras].itertuples(index=False, name=None)
        ]
    return frame[known]


def _with_seq(fp: pd.DataFrame) -> pd.DataFrame:
    """Derive ``seq`` (1–6 in running order) where the source does not give it: by km in the
    track's normal direction (``feature_points``: decreasing on U) or by increasing ``pos_m``
    (``track_feature_points``)."""
    if fp.empty or fp["seq"].notna().all():
        return fp
    fp = fp.copy()
    if "track_id" in fp.columns:
        keys, order = ["track_id", "feature_id"], fp["pos_m"].to_numpy(dtype=float, na_value=np.nan)
    else:
        keys = ["line_code", "track", "feature_id"]
        sign = np.where(fp["track"].astype(object) == Track.UP.value, -1.0, 1.0)
        order = fp["km_m"].to_numpy(dtype=float, na_value=np.nan) * sign
    fp["_order"] = order
    fp["_pos"] = np.arange(len(fp))
    fp = fp.sort_values([*keys, "_order", "_pos"], kind="stable")
    seq = fp.groupby(keys, dropna=False).cumcount() + 1
    fp["seq"] = fp["seq"].fillna(seq.astype("Int64"))
    return fp.sort_values("_pos").drop(columns=["_order", "_pos"])


def _line_codes(tables: dict[str, pd.DataFrame], files: dict[str, str]) -> list[Finding]:
    """Build ``lines`` from the codes in use when absent; otherwise every code must be listed."""
    used: set[str] = set()
    for name in ("gis", "balises", "feature_points", "km_breaks", "tracks", "switches"):
        used |= set(tables[name]["line_code"].dropna().unique().astype(str))
    lines = tables[LINES.name]
    if LINES.name not in files:
        tables[LINES.name] = pd.DataFrame(
            {"line_code": sorted(used), "name": [None] * len(used), "attributes_json": [None] * len(used)}
        )
        return []
    known = set(lines["line_code"].dropna().astype(str))
    return [
        Finding(
            "source.unknown_line",
            Severity.ERROR,
            "lines",
            f"line_code '{code}' is used but not listed in lines",
            keys={"line_code": code},
            file=files[LINES.name],
            value=code,
        )
        for code in sorted(used - known)
    ]


def write_source_set(
    network: Network,
    folder: Path,
    *,
    force: bool = False,
    inputs: Iterable[Path | str] = (),
    extra_files: Mapping[str, str] | None = None,
) -> Path:
    """Write a network as CSV source files (the format ``db build`` reads back), under the
    output rule of :mod:`dbtools.atomic` (``inputs``: never replaced). ``extra_files``: file
    name → UTF-8 text written beside them in the same atomic step (an import report)."""
    from dbtools.atomic import atomic_folder

    folder = Path(folder)
    empty = folder.is_dir() and not any(folder.iterdir())
    with atomic_folder(folder, force=force or empty, inputs=inputs) as tmp:  # an empty folder may be replaced
        for name, table in SOURCE_TABLES.items():
            frame = network.tables.get(name)
            if frame is None or (not table.required and frame.empty):
                continue
            cols = [c for c in table.column_names if c != "attributes_json"]
            frame[cols].to_csv(tmp / f"{name}.csv", index=False, lineterminator="\n")
        write_declaration(network.meta, tmp / NETWORK_FILE)
        for name, text in (extra_files or {}).items():
            (tmp / name).write_text(text, encoding="utf-8")
    return folder
