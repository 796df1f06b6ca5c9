"""Every finding rule id ``db validate`` and ``db import`` report, with its meaning and fix:
the catalogue behind ``docs/reference/rules.md`` (``python -m cli.schema_docs`` writes it).

The rule modules (:mod:`dbtools.rules`) document their rules in their docstrings as bullets
``* ``family.rule`` (severity) — meaning. Fix: …``; :func:`rule_catalog` reads them. Rules
raised outside those modules (the source reader, the schema checks of every frame, the DB
file checks, the railML importer) are described in :data:`OTHER_RULES` below.
``tests/test_docs.py`` fails when the code reports a rule id this catalogue does not hold.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from importlib import import_module

#: The rule families (the part of a rule id before the dot), as SARIF's short description.
FAMILIES = {
    "schema": "Source and table schema: types, required values, enumerations, ranges, keys",
    "source": "Source set files and line codes",
    "gis": "GIS grid: 20 m steps, breaks, spacing, spikes, area",
    "balise": "Balises: initial pairs, C balises, ETCS balise groups, identification windows, GIS range",
    "topology": "Network topology: track/switch references, switch ports and routes, connection gaps, km, lengths, "
    "crossover angles, open ends, balise identification along routes",
    "feature": "Feature points: rows, radius and direction against the GIS curvature, straights",
    "db": "DB file: SQLite integrity, foreign keys, meta and content hash",
    "railml": "railML import",
}

#: The modules whose docstrings list their rules.
RULE_MODULES = (
    "dbtools.rules.area",
    "dbtools.rules.balise_groups",
    "dbtools.rules.balises",
    "dbtools.rules.features",
    "dbtools.rules.gis",
    "dbtools.rules.heights",
    "dbtools.rules.schema",
    "dbtools.rules.topology",
    "dbtools.rules.topology_geometry",
    "dbtools.rules.track_geometry",
)

#: rule id → (severity, meaning and fix) for the rules raised outside :data:`RULE_MODULES`.
OTHER_RULES: dict[str, tuple[str, str]] = {
    "schema.missing_column": ("error", "a required column is not in the file's header. Fix: add the column."),
    "schema.unknown_column": (
        "warning",
        "a column the table does not declare (a typo: the finding suggests the closest name). Fix: rename or "
        "delete it.",
    ),
    "schema.type": ("error", "a cell is not of the column's type (a word in a number column). Fix: the cell."),
    "schema.null": ("error", "an empty cell where the column requires a value. Fix: fill it."),
    "schema.enum": (
        "error",
        "a value outside the column's allowed values (the finding suggests the closest). Fix: the cell.",
    ),
    "schema.range": (
        "error",
        "a value outside the column's range (its unit and limits are in the message), or a GIS point more than "
        "2 km outside the operating area. Fix: the cell (a lost decimal point, a wrong unit, swapped lat/lon).",
    ),
    "schema.duplicate_key": ("error", "two rows with the same primary key. Fix: delete or renumber one."),
    "schema.check": ("error", "a row fails one of the table's declared checks (named in the message). Fix: the row."),
    "schema.not_finite": ("error", "NaN or infinity in a number column. Fix: the cell."),
    "schema.empty_table": (
        "error",
        "a table the DB needs has no rows (warning for an optional one). Fix: fill the source file.",
    ),
    "source.missing_file": ("error", "a required source file (CSV or XLSX) is not in the source set. Fix: add it."),
    "source.delimiter": (
        "error",
        "the fields are separated by semicolons or tabs, not commas. Fix: save the file as comma-separated CSV.",
    ),
    "source.duplicate_column": ("error", "a column name appears twice in the header. Fix: rename or delete one."),
    "source.encoding": (
        "warning",
        "the file is not UTF-8 (read as the encoding the message names). Fix: save it as UTF-8.",
    ),
    "source.numeric_code": (
        "error",
        "an Excel cell holds a code (line, station) as a number, which has lost its leading zeros. Fix: format the "
        "column as text and type the code again.",
    ),
    "source.hidden_sheet": (
        "error / warning",
        "an .xlsx workbook's sheet is hidden: an error when it is the one read (a hidden sheet often holds old "
        "data), a warning when it was skipped for the first visible one. Fix: unhide or delete it, or name the "
        "sheet like the table.",
    ),
    "source.date_in_text": (
        "error",
        "an .xlsx cell of a text column (a code) holds a date: Excel turned what was typed into a date. Fix: "
        "format the column as Text and type the value again.",
    ),
    "source.unknown_line": ("error", "a line_code is used but not listed in lines. Fix: add the line to lines."),
    "db.integrity": ("error", "SQLite's integrity_check fails: the file is damaged. Fix: build the DB again."),
    "db.foreign_key": (
        "error",
        "a row references a missing row of another table (foreign_key_check). Fix: build the DB again from its "
        "sources.",
    ),
    "db.meta": (
        "error",
        "the DB's meta lacks a required key (version, content_hash, …): not a DB db build wrote. Fix: build it.",
    ),
    "db.content_hash": (
        "error",
        "the content no longer matches the hash stored when it was built (edited by hand, or corrupted). Fix: "
        "build the DB again; never edit a built DB.",
    ),
    "railml.version": ("error", "not railML 2.x or 3.x. Fix: export the file as railML 2.2–2.5 or 3.1–3.2."),
    "railml.xsd": ("error", "the file fails the XML schema given with --xsd. Fix: the element the message names."),
    "railml.missing_id": ("error", "an element that must have an @id has none. Fix: give it one."),
    "railml.duplicate_id": ("error", "an id is used twice. Fix: make it unique."),
    "railml.value": ("error", "an attribute that must be a number is not. Fix: the attribute."),
    "railml.units": ("error", "a positioning system not in metres. Fix: export kilometrage in metres."),
    "railml.undefined_ref": ("error", "a reference names no linear positioning system in metres. Fix: the ref."),
    "railml.undefined_track": ("error", "a netElementRef names no netElement. Fix: the reference."),
    "railml.dangling_ref": (
        "warning",
        "a netRelation names a netElement that is not in the file (an extract's edge): dropped.",
    ),
    "railml.topology": ("warning", "a netRelation with positions other than 0/1: dropped. Fix: the relation."),
    "railml.position": ("error", "a located element (balise, signal, …) has no spotLocation. Fix: locate it."),
    "railml.no_mileage": (
        "error",
        "a location has neither a linear coordinate nor a mileage on its netElement. Fix: add one.",
    ),
    "railml.mileage": ("error", "a mileage change without its from/to spot locations. Fix: the mileageChange."),
    "railml.geocoord": ("error", "a geometric coordinate that cannot be read. Fix: the coordinate."),
    "railml.geometry": (
        "warning",
        "no coordinates on any imported track: the GIS grid is empty. Fix: build one with trainpos gis grid.",
    ),
    "railml.curve": (
        "warning",
        "a curve that cannot become six feature-point rows (too short, no radius, no straight). Fix: the curve or "
        "the feature_points file after import.",
    ),
    "railml.switch_open": ("warning", "a switch that cannot be imported (the reason is in the message)."),
    "railml.switch_open_port": (
        "warning",
        "a switch whose diverging branch leads out of the file: imported with that port empty.",
    ),
    "railml.switch_side": (
        "warning",
        "a switch without its side (@course): b1 taken as the through route, b2 the branch. Fix: state it.",
    ),
    "railml.pair": ("error", "a group named an initial pair without exactly 2 balises. Fix: the group."),
    "railml.no_pair": ("warning", "a balise with no initial pair before it on its track: no C balise is made."),
    "railml.balise_count": ("warning", "a balise group states a number of balises other than the file holds."),
    "railml.balise_identity": (
        "warning",
        "a balise group without an ETCS identity (NID_C/NID_BG): imported as G rows with nid_bg empty.",
    ),
    "railml.quirk": ("warning", "a known exporter quirk read as meant (the message says how)."),
    "railml.unmapped": ("warning", "an element trainpos has no table for: not imported (named in the report)."),
    "railml.nothing_imported": (
        "error",
        "the file holds balises or tracks and none could be imported (the warnings say why); nothing written.",
    ),
}

_BULLET = re.compile(
    r"^\* ``([a-z]+\.[a-z_0-9]+)``(?: / ``([a-z]+\.[a-z_0-9]+)``)? \(([^)]*)\) — (.*?)(?=^\* |\n\n|\Z)", re.S | re.M
)
_ROLE = re.compile(r":(?:func|class|meth|mod|data|attr):`~?([^`]+)`")


@dataclass(frozen=True)
class Rule:
    rule_id: str
    severity: str
    meaning: str  # meaning and fix, one paragraph
    source: str  # the module that documents it


def _clean(text: str) -> str:
    text = _ROLE.sub(lambda m: f"`{m.group(1).rsplit('.', 1)[-1]}`", text)
    return " ".join(text.replace("``", "`").split()).rstrip(";").rstrip()


def rule_catalog() -> dict[str, Rule]:
    """Every documented rule id, sorted."""
    out: dict[str, Rule] = {}
    for name in RULE_MODULES:
        doc = import_module(name).__doc__ or ""
        for m in _BULLET.finditer(doc):
            for rid in filter(None, (m.group(1), m.group(2))):
                out.setdefault(rid, Rule(rid, m.group(3), _clean(m.group(4)), name))
    for rid, (severity, meaning) in OTHER_RULES.items():
        out[rid] = Rule(rid, severity, meaning, "dbtools.rules.catalog")  # the general meaning first
    return dict(sorted(out.items()))


def rule_ids_in_source(texts: dict[str, str]) -> set[str]:
    """The rule ids string literals of ``texts`` (path → Python source) name."""
    pattern = re.compile(r"(?:{})\.[a-z_0-9]+".format("|".join(FAMILIES)))
    found = set()
    for path, text in texts.items():
        for node in ast.walk(ast.parse(text, filename=path)):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and pattern.fullmatch(node.value):
                found.add(node.value)
    return found
