"""Random damage to source sets (issue 15, property tests): ``db validate`` and ``db build``
never crash, always exit with a documented code, never modify an input, and never write a
DB when the source set has an error finding; a DB they do write validates as its sources do.

Each example copies the bundled sample source set and damages it by a few random
operations of the kinds maintenance staff produce — rows dropped or duplicated, cells
corrupted (empty, text, huge, non-finite, railway km gone wrong, a stray quote), columns
swapped or reordered, files truncated (mid-line, mid-character), missing, empty or
header-only, text in number columns, another encoding (Shift-JIS, UTF-16, Latin-1),
another delimiter, a BOM, trailing garbage, a sheet saved as .xlsx with numeric codes, a
workbook whose first sheet is a hidden stale copy, an Excel date in a text column, a km typed
ten times too large (issue 32: never silently read; a DB that is released is exactly the one
validated — each example that builds is released and its release verified).

``db build`` refuses source errors (the rules of reading: types, enumerations, ranges,
keys, the file-level findings); the cross-table rules of ``db validate`` (GIS geometry,
balise pairs …) are reported by validate and refused by ``db release``, as README says.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import openpyxl
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner, Result

from cli.main import app
from dbtools.sample_network import sample_source_dir
from dbtools.sources import read_source_set
from schemas.enums import Severity

FILES = ("gis", "balises", "feature_points", "lines")
CELLS = ["", "abc", "1e400", "nan", "-inf", "-1", "１２", "12k3x4", "9" * 400, "01", '"', " 5", "I3", "D ", "0420"]
OPS = (
    "drop_rows",
    "duplicate_rows",
    "corrupt_cell",
    "swap_columns",
    "reorder_columns",
    "truncate",
    "text_in_numbers",
    "delete_file",
    "header_only",
    "empty_file",
    "encoding",
    "delimiter",
    "bom",
    "garbage",
    "xlsx",
    "hidden_sheet",
    "excel_date",
    "km_times_ten",
)


def _digest(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


def _rows(path: Path) -> list[list[str]]:
    return [line.split(",") for line in path.read_text(encoding="utf-8").splitlines()]


def _write_rows(path: Path, rows: list[list[str]]) -> None:
    path.write_text("".join(",".join(r) + "\n" for r in rows), encoding="utf-8")


def _edit_rows(path: Path, op: str, frac: float, cell: str) -> None:
    """Row- and cell-level damage of a comma-separated file (as the sample files are)."""
    rows = _rows(path)
    if not rows:
        return
    head, body = rows[0], rows[1:]
    n, width = len(body), len(head)
    pick = min(int(frac * n), n - 1) if n else 0
    col = int(frac * 7919) % width
    if op == "drop_rows":
        body = [r for i, r in enumerate(body) if (i * 2654435761 % 97) / 97 >= frac]
    elif op == "duplicate_rows":
        body = body + body[pick : pick + max(int(n * frac * 0.3), 1)]
    elif op == "corrupt_cell" and n and col < len(body[pick]):
        body[pick][col] = cell
    elif op == "swap_columns" and width > 1:
        other = (col + 1) % width
        head[col], head[other] = head[other], head[col]
    elif op == "reorder_columns":
        order = sorted(range(width), key=lambda i: (i * 31 + int(frac * 100)) % width)
        head, body = [head[i] for i in order], [[r[i] if i < len(r) else "" for i in order] for r in body]
    elif op == "text_in_numbers":
        for r in body[: max(int(n * frac), 1)]:
            if col < len(r):
                r[col] = "twelve"
    _write_rows(path, [head, *body])


def _to_xlsx(path: Path) -> None:
    """The file as a workbook: numbers where a cell parses as one (codes lose zeros)."""
    book = openpyxl.Workbook()
    ws = book.active
    ws.title = path.stem
    for line in path.read_text(encoding="utf-8").splitlines():
        cells: list[object] = []
        for c in line.split(","):
            try:
                cells.append(float(c) if c.strip() else None)
            except ValueError:
                cells.append(c)
        ws.append(cells)
    book.save(path.with_suffix(".xlsx"))
    path.unlink()


def _to_xlsx_with(path: Path, op: str, frac: float) -> None:
    """As :func:`_to_xlsx`, with a hidden stale first sheet (``hidden_sheet``) or a date in a
    random text cell (``excel_date``: what Excel makes of a code such as 1-1)."""
    import datetime

    _to_xlsx(path)
    xlsx = path.with_suffix(".xlsx")
    book = openpyxl.load_workbook(xlsx)
    ws = book.active
    if op == "hidden_sheet":
        stale = book.create_sheet("old", 0)
        for row in list(ws.iter_rows(values_only=True))[: max(2, int(ws.max_row * frac))]:
            stale.append(list(row))
        stale.sheet_state = "hidden"
    else:
        texts = [(r, c) for r in range(2, ws.max_row + 1) for c in range(1, ws.max_column + 1)]
        texts = [rc for rc in texts if isinstance(ws.cell(*rc).value, str)]
        if texts:
            ws.cell(*texts[int(frac * len(texts)) % len(texts)]).value = datetime.datetime(2026, 1, 1)
    book.save(xlsx)


def _km_times_ten(path: Path, frac: float) -> None:
    rows = _rows(path)
    cols = [k for k, c in enumerate(rows[0]) if c.endswith("km_equipment_m") or c == "km_m"] if rows else []
    if len(rows) > 1 and cols:
        r = 1 + int(frac * (len(rows) - 1)) % (len(rows) - 1)
        try:
            rows[r][cols[0]] = repr(float(rows[r][cols[0]]) * 10.0)
        except (ValueError, IndexError):
            return
        _write_rows(path, rows)


def _damage(src: Path, op: str, name: str, frac: float, cell: str) -> None:
    path = src / f"{name}.csv"
    if not path.exists():
        return
    raw = path.read_bytes()
    if op == "truncate":
        path.write_bytes(raw[: int(len(raw) * frac)])
    elif op == "delete_file":
        path.unlink()
    elif op == "header_only":
        path.write_bytes(raw.split(b"\n", 1)[0] + b"\n")
    elif op == "empty_file":
        path.write_bytes(b"")
    elif op == "encoding":
        text = raw.decode("utf-8", errors="replace").replace("Kawagoe", "川越")
        encoding = ("cp932", "utf-16", "latin-1")[int(frac * 3) % 3]
        path.write_bytes(text.encode(encoding, errors="replace"))
    elif op == "delimiter":
        path.write_bytes(raw.replace(b",", b";"))
    elif op == "bom":
        path.write_bytes(b"\xef\xbb\xbf" + raw)
    elif op == "garbage":
        path.write_bytes(raw + bytes(range(int(frac * 256), 256)))
    elif op == "xlsx":
        try:
            _to_xlsx(path)
        except UnicodeDecodeError:
            return  # damaged beyond a spreadsheet already
    elif op in ("hidden_sheet", "excel_date"):
        try:
            _to_xlsx_with(path, op, frac)
        except UnicodeDecodeError:
            return
    elif op == "km_times_ten":
        try:
            _km_times_ten(path, frac)
        except UnicodeDecodeError:
            return
    else:
        try:
            _edit_rows(path, op, frac, cell)
        except UnicodeDecodeError:
            return


def _clean(r: Result, what: object) -> None:
    assert "Traceback" not in r.output and "internal error" not in r.output, (what, r.output)
    assert r.exception is None or isinstance(r.exception, SystemExit), (what, repr(r.exception))


damage = st.lists(
    st.tuples(st.sampled_from(OPS), st.sampled_from(FILES), st.floats(0.02, 0.98), st.sampled_from(CELLS)),
    min_size=1,
    max_size=3,
)


@pytest.mark.slow
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(ops=damage)
def test_damaged_source_sets_never_crash_nor_build_with_errors(
    ops: list[tuple[str, str, float, str]], tmp_path_factory: pytest.TempPathFactory
) -> None:
    work = tmp_path_factory.mktemp("case")
    src = work / "src"
    shutil.copytree(sample_source_dir(), src)
    for op, name, frac, cell in ops:
        _damage(src, op, name, frac, cell)
    before = _digest(src)
    runner = CliRunner()
    validate = runner.invoke(app, ["db", "validate", str(src), "--format", "json"])
    _clean(validate, ops)
    assert validate.exit_code in (0, 1, 2), (ops, validate.output)
    out = work / "net.sqlite"
    build = runner.invoke(app, ["db", "build", str(src), "--out", str(out), "--version", "t1"])
    _clean(build, ops)
    assert build.exit_code in (0, 1, 2), (ops, build.output)
    assert _digest(src) == before, "an input was modified"
    assert sorted(p.name for p in work.iterdir() if p.name != "releases") == (
        ["net.sqlite", "src"] if build.exit_code == 0 else ["src"]
    )
    if validate.exit_code == 2:  # unreadable: build refuses it the same way
        assert build.exit_code == 2, (ops, build.output)
        return
    source_errors = [f for f in read_source_set(src)[1] if f.severity == Severity.ERROR]
    assert (build.exit_code == 0) == (not source_errors), (ops, build.output, source_errors[:3])
    report = json.loads(validate.stdout)
    assert report["ok"] == (validate.exit_code == 0)
    if build.exit_code == 0:  # the DB validates as its sources do (the same content)
        db_report = runner.invoke(app, ["db", "validate", str(out), "--format", "json"])
        _clean(db_report, ops)
        errors = {f["rule"] for f in report["findings"] if f["severity"] == "error"}
        db_errors = {f["rule"] for f in json.loads(db_report.stdout)["findings"] if f["severity"] == "error"}
        assert db_errors == errors, (ops, db_errors, errors)
        if not errors:  # released: what the registry holds is what was validated, and it verifies
            reg = work / "releases"
            rel = runner.invoke(app, ["db", "release", str(out), "--registry", str(reg)])
            _clean(rel, ops)
            assert rel.exit_code == 0, (ops, rel.output)
            check = runner.invoke(app, ["db", "verify-release", "--registry", str(reg)])
            assert check.exit_code == 0, (ops, check.output)
