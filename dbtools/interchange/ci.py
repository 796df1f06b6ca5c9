"""Findings for CI systems: SARIF 2.1.0 (GitHub code scanning, GitLab, Azure DevOps) and
JUnit XML (GitLab, Jenkins, most CI test reports).

SARIF (OASIS SARIF 2.1.0, validated in the tests against the OASIS JSON schema): one run
of the ``trainpos`` driver; one ``reportingDescriptor`` per rule id found (its family as the
short description, its meaning and fix from :mod:`dbtools.rules.catalog` as the full one); one result per
finding with ``level`` error or warning, the message, and a location — for a finding in a
source set the file (URI relative to the working directory when inside it) with
``region.startLine`` = the file line and, for CSV, ``startColumn``/``endColumn`` of the
named column's cell on that line; for a finding in a DB file the DB as the artifact and a
``logicalLocation`` ``table/key=value,…`` (rows of a DB have no lines). The finding's keys,
value and limit go to the result's ``properties``.

JUnit: one ``testsuite`` with a test case per finding (``classname`` = the rule family,
``name`` = rule id and where) — an error is a ``failure``, a warning passes with the
message in ``system-out`` (a failure under ``strict``) — plus a ``consistency`` test case
that fails when anything fails.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape, quoteattr

from dbtools.rules.catalog import FAMILIES, rule_catalog
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.jsonable import jsonable

SARIF_SCHEMA = "https://docs.oasis-open.org/sarif/sarif/v2.1.0/errata01/os/schemas/sarif-schema-2.1.0.json"


def _uri(file: str) -> str:
    p = Path(file)
    try:
        return p.resolve().relative_to(Path.cwd().resolve()).as_posix()
    except ValueError:
        return p.resolve().as_uri()


def _columns(file: str, row: int, column: str, cache: dict[str, list[str]]) -> tuple[int, int] | None:
    """(startColumn, endColumn) of ``column``'s cell on file line ``row`` of a CSV (1-based, end exclusive)."""
    if not file.lower().endswith(".csv"):
        return None
    if file not in cache:
        try:
            cache[file] = Path(file).read_text(encoding="utf-8-sig").splitlines()
        except (OSError, UnicodeDecodeError):
            cache[file] = []
    lines = cache[file]
    if not lines or not 1 <= row <= len(lines):
        return None
    header = next(csv.reader([lines[0]]))
    if column not in header:
        return None
    k = header.index(column)
    fields = next(csv.reader([lines[row - 1]]), [])
    if k >= len(fields) or any('"' in f or "," in f for f in fields[: k + 1]):
        return None
    start = 1 + sum(len(f) + 1 for f in fields[:k])
    return start, start + max(len(fields[k]), 1)


def _logical(f: Finding) -> dict[str, Any]:
    keys = ",".join(f"{k}={v}" for k, v in f.keys.items())
    name = f"{f.table}/{keys}" if keys else f.table
    return {"name": name, "fullyQualifiedName": name, "kind": "object"}


def _location(f: Finding, target: str | None, cache: dict[str, list[str]]) -> dict[str, Any]:
    if f.file:
        phys: dict[str, Any] = {"artifactLocation": {"uri": _uri(f.file)}}
        if f.row:
            region: dict[str, Any] = {"startLine": int(f.row)}
            cols = _columns(f.file, int(f.row), f.column, cache) if f.column else None
            if cols:
                region.update(startColumn=cols[0], endColumn=cols[1])
            phys["region"] = region
        return {"physicalLocation": phys}
    loc: dict[str, Any] = {"logicalLocations": [_logical(f)]}
    if target:
        loc["physicalLocation"] = {"artifactLocation": {"uri": _uri(target)}}
    return loc


def sarif(findings: Sequence[Finding], *, target: str | None = None, tool_version: str = "0") -> dict[str, Any]:
    """The SARIF 2.1.0 log of ``findings`` (module doc); ``target`` names the validated DB."""
    rules = sorted({f.rule for f in findings})
    index = {r: i for i, r in enumerate(rules)}
    catalog = rule_catalog() if rules else {}
    descriptors = []
    for r in rules:
        descriptor: dict[str, Any] = {
            "id": r,
            "name": r.replace(".", "_"),
            "shortDescription": {"text": FAMILIES.get(r.split(".")[0], r)},
        }
        if r in catalog:  # its meaning and fix, as docs/reference/rules.md gives them
            descriptor["fullDescription"] = {"text": catalog[r].meaning}
        descriptors.append(descriptor)
    cache: dict[str, list[str]] = {}
    results = []
    for f in findings:
        results.append(
            {
                "ruleId": f.rule,
                "ruleIndex": index[f.rule],
                "level": "error" if f.severity == Severity.ERROR else "warning",
                "message": {"text": f"{f.where}: {f.message}"},
                "locations": [_location(f, target, cache)],
                "properties": jsonable(
                    {"table": f.table, "keys": f.keys, "value": f.value, "limit": f.limit, "column": f.column}, 6
                ),
            }
        )
    driver = {"name": "trainpos", "version": tool_version, "semanticVersion": tool_version, "rules": descriptors}
    return {"$schema": SARIF_SCHEMA, "version": "2.1.0", "runs": [{"tool": {"driver": driver}, "results": results}]}


def sarif_text(findings: Sequence[Finding], **kw: Any) -> str:
    return json.dumps(sarif(findings, **kw), ensure_ascii=False, indent=2) + "\n"


def junit(findings: Sequence[Finding], *, target: str, strict: bool = False) -> str:
    """JUnit XML of ``findings`` (module doc)."""
    cases = []
    failed = 0
    for f in findings:
        is_fail = f.severity == Severity.ERROR or strict
        failed += is_fail
        name = quoteattr(f"{f.rule} {f.where}")
        cls = quoteattr(f"trainpos.db.validate.{f.rule.split('.')[0]}")
        body = (
            f"<failure type={quoteattr(f.rule)} message={quoteattr(f.message)}>{escape(str(f))}</failure>"
            if is_fail
            else f"<system-out>{escape(str(f))}</system-out>"
        )
        cases.append(f"    <testcase classname={cls} name={name} file={quoteattr(f.file or target)}>{body}</testcase>")
    verdict = "" if not failed else f'<failure type="trainpos.db.validate" message="{failed} finding(s) fail"/>'
    cases.append(
        f'    <testcase classname="trainpos.db.validate" name={quoteattr("consistency " + target)}>{verdict}</testcase>'
    )
    buf = io.StringIO()
    buf.write('<?xml version="1.0" encoding="UTF-8"?>\n')
    buf.write(f'<testsuites name="trainpos db validate" tests="{len(cases)}" failures="{failed + bool(failed)}">\n')
    buf.write(
        f'  <testsuite name={quoteattr("db validate " + target)} tests="{len(cases)}" '
        f'failures="{failed + bool(failed)}" errors="0" skipped="0">\n'
    )
    buf.write("\n".join(cases) + "\n  </testsuite>\n</testsuites>\n")
    return buf.getvalue()
