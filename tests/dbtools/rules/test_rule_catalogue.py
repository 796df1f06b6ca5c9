"""The rule catalogue (dbtools.rules.catalogue): every emitted rule id documented with meaning and fix."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from dbtools.rules.catalogue import RULE_ID, catalogue_from, parse_docstring, rule_catalogue

ROOT = Path(__file__).resolve().parents[3]

#: Ids built at run time: ``schemas.frames`` emits ``schema.{_rule_for(check)}``.
DYNAMIC = {"schema.null", "schema.enum", "schema.range", "schema.duplicate_key", "schema.check"}


def emitted_rule_ids() -> dict[str, str]:
    """Rule-id literals passed to a call (Finding(…) or a helper making one), bound to a name
    or in a tuple (a loop over rules) in dbtools/ and schemas/ → the first file that has it."""
    out: dict[str, str] = {}
    for name in ("dbtools", "schemas"):
        for path in sorted((ROOT / name).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                values: list[ast.expr] = []
                if isinstance(node, ast.Call):
                    values = [*node.args, *(k.value for k in node.keywords)]
                elif isinstance(node, ast.Assign | ast.AnnAssign) and node.value is not None:
                    values = [node.value]
                elif isinstance(node, ast.Tuple):  # a table of rules looped over
                    values = list(node.elts)
                for v in values:
                    if isinstance(v, ast.Constant) and isinstance(v.value, str) and RULE_ID.match(v.value):
                        out.setdefault(v.value, str(path.relative_to(ROOT)))
    return out


def test_the_scan_finds_rule_ids_of_every_kind() -> None:
    ids = emitted_rule_ids()
    # a Finding(…) in a rule module, a helper call in an importer, a module constant, schemas
    assert {"balise.pair_count", "railml.value", "railml.xsd", "schema.type", "db.meta", "gis.height_grade"} <= set(ids)
    assert "gis.csv" not in ids  # a file name, not a rule


def test_every_emitted_rule_id_has_meaning_and_fix() -> None:
    catalogue = rule_catalogue()
    emitted = set(emitted_rule_ids()) | DYNAMIC
    missing = sorted(r for r in emitted if r not in catalogue)
    assert not missing, f"rule ids without a docstring bullet: {missing}"
    bare = sorted(r for r in emitted if not catalogue[r].meaning or not catalogue[r].fix)
    assert not bare, f"rule ids without meaning or 'Fix:': {bare}"


def test_every_catalogued_rule_is_emitted() -> None:
    """A bullet for a rule nobody emits is a stale doc (or a typo in an id)."""
    stale = sorted(set(rule_catalogue()) - set(emitted_rule_ids()) - DYNAMIC)
    assert not stale


def test_parse_a_bullet_with_continuation_lines_and_without_severity() -> None:
    doc = """Rules.

* ``gis.km_grid`` (error) — km is not a multiple
  of 20 m. Fix: round the km.
* ``schema.empty_table`` — a header-only file. Fix: add rows.
Not part of it.

* ``topology.gap`` (warning / error) — far apart.
"""
    assert parse_docstring(doc) == [
        ("gis.km_grid", "error", "km is not a multiple of 20 m.", "round the km."),
        ("schema.empty_table", "", "a header-only file.", "add rows."),
        ("topology.gap", "warning / error", "far apart.", ""),
    ]


def test_a_rule_documented_in_two_modules_gets_both(tmp_path: Path) -> None:
    for name, text in (("a", "Fix: one."), ("b", "Fix: two.")):
        path = tmp_path / "dbtools" / f"{name}.py"
        path.parent.mkdir(exist_ok=True)
        path.write_text(f'"""Doc.\n\n* ``schema.range`` (error) — {name}. {text}\n"""\n', encoding="utf-8")
    (tmp_path / "schemas").mkdir()
    doc = catalogue_from(tmp_path)["schema.range"]
    assert (doc.meaning, doc.fix, doc.modules) == ("a. b.", "one. two.", ("dbtools.a", "dbtools.b"))
    assert doc.anchor == "schema.range" and doc.family == "schema" and doc.summary == "A. b"
    assert doc.markdown().startswith("**schema.range** (error): a. b.\n\n**Fix:** one. two.")


@pytest.mark.parametrize("rule", ["balise.pair_count", "topology.gap", "db.content_hash"])
def test_known_rules_have_their_module(rule: str) -> None:
    assert rule_catalogue()[rule].modules


def test_markup_becomes_markdown_and_plain_text() -> None:
    doc = rule_catalogue()["topology.gap"]
    assert "``" not in doc.markdown() and ":mod:" not in doc.markdown() and "`connection_gap_m`" in doc.markdown()
    assert "`" not in doc.text() and "Fix: " in doc.text()
    assert doc.summary.startswith("The coordinates of two joined ends are more than connection_gap_m apart")
