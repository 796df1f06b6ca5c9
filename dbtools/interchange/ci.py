"""Findings for CI systems: SARIF 2.1.0 (GitHub code scanning, GitLab, Azure DevOps) and
JUnit XML (GitLab, Jenkins, most CI test reports).

SARIF (OASIS SARIF 2.1.0, validated in the tests against the OASIS JSON schema): one run
of the ``trainpos`` driver; one ``reportingDescriptor`` per rule id found, from the rule
catalogue (:func:`dbtools.rules.catalogue.rule_catalogue`): ``shortDescription`` (the
meaning's first clause), ``fullDescription`` (the meaning), ``help`` (text and Markdown with
the fix), ``helpUri`` = ``HELP_URI_BASE`` + ``docs/reference/rules.md#<rule id>``
(``help_uri_base``, ``db validate --help-uri-base``; by default the repository-relative path,
which code-scanning platforms resolve against the repository — SARIF §3.49.12 prefers an
absolute URI: give the base, e.g. ``https://github.com/ORG/trainpos/blob/main/``), the
``defaultConfiguration.level`` of a rule with one severity and the family as a tag.

One result per finding with ``level`` error or warning, the message and a location. Every
artifact URI is relative with a ``uriBaseId`` that ``run.originalUriBaseIds`` defines:
``%SRCROOT%`` the working folder (GitHub's convention), ``TARGETROOT`` the validated source
set (or the DB's folder) for a file outside the working folder; only a path on another drive
stays an absolute ``file:`` URI. The location of a finding:

* in a source set: the file with ``region.startLine`` = the file line and, for CSV,
  ``startColumn``/``endColumn`` of the named column's cell on that line; a finding without a
  file (a whole-network rule) names the table's file in the set (``TABLE.csv``/``.xlsx``);
* in a DB file: the DB as the artifact and a ``logicalLocation`` ``table/key=value,…`` (rows
  of a DB have no lines); when the DB records the source file the table was built from (meta
  ``source_sha256:<file>``), a ``relatedLocation`` names that file under the uriBaseId
  ``SOURCESET`` (where the set lies is not recorded: a consumer maps it).

The finding's keys, value and limit go to the result's ``properties``.

JUnit: one ``testsuite`` with a test case per finding (``classname`` = the rule family,
``name`` = rule id and where) — an error is a ``failure``, a warning passes with the
message in ``system-out`` (a failure under ``strict``) — plus a ``consistency`` test case
that fails when anything fails.
"""

from __future__ import annotations

import csv
import io
import json
import os
import sqlite3
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape, quoteattr

from dbtools.rules.catalogue import FAMILIES, rule_catalogue
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.jsonable import jsonable

SARIF_SCHEMA = "https://docs.oasis-open.org/sarif/sarif/v2.1.0/errata01/os/schemas/sarif-schema-2.1.0.json"
#: The rule reference, relative to the repository (and to ``help_uri_base``).
RULES_DOC = "docs/reference/rules.md"
SRCROOT = "%SRCROOT%"
TARGETROOT = "TARGETROOT"
SOURCESET = "SOURCESET"
__all__ = ["FAMILIES", "RULES_DOC", "junit", "rule_descriptor", "sarif", "sarif_text"]


@dataclass(frozen=True)
class _Bases:
    """The folders relative URIs are taken against: ``%SRCROOT%`` first, then ``TARGETROOT``."""

    cwd: Path
    target_root: Path | None

    def location(self, file: str | Path) -> dict[str, Any]:
        """An ``artifactLocation``: a relative URI and its uriBaseId (module doc)."""
        p = Path(file).resolve()
        for base_id, root in ((SRCROOT, self.cwd), (TARGETROOT, self.target_root)):
            if root is not None and p.is_relative_to(root):
                return {"uri": _rel(p, root), "uriBaseId": base_id}
        try:
            return {"uri": Path(os.path.relpath(p, self.cwd)).as_posix(), "uriBaseId": SRCROOT}
        except ValueError:  # another drive (Windows): no relative path exists
            return {"uri": p.as_uri()}

    def original(self, used: set[str]) -> dict[str, Any]:
        """``run.originalUriBaseIds`` of the bases ``used`` (absolute ``file:`` URIs ending in /)."""
        roots = {SRCROOT: self.cwd, TARGETROOT: self.target_root}
        return {k: {"uri": root.as_uri().rstrip("/") + "/"} for k, root in roots.items() if k in used and root}


def _rel(p: Path, root: Path) -> str:
    rel = p.relative_to(root).as_posix()
    return "./" if rel == "." else rel + ("/" if p.is_dir() else "")


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


def _table_file(folder: Path, table: str) -> Path | None:
    """The source file of ``table`` in a source-set folder, if there is one."""
    for suffix in (".csv", ".xlsx"):
        if (folder / f"{table}{suffix}").is_file():
            return folder / f"{table}{suffix}"
    return None


@dataclass(frozen=True)
class _Target:
    """What was validated: a source-set folder or a DB file (and the source files it records)."""

    path: Path | None
    source_files: Mapping[str, str]
    bases: _Bases

    @property
    def is_db(self) -> bool:
        return self.path is not None and not self.path.is_dir()


def _file_location(file: str, row: int | None, column: str | None, t: _Target, cache: dict[str, list[str]]) -> Any:
    phys: dict[str, Any] = {"artifactLocation": t.bases.location(file)}
    if row:
        region: dict[str, Any] = {"startLine": int(row)}
        cols = _columns(file, int(row), column, cache) if column else None
        if cols:
            region.update(startColumn=cols[0], endColumn=cols[1])
        phys["region"] = region
    return phys


def _locations(f: Finding, t: _Target, cache: dict[str, list[str]]) -> dict[str, Any]:
    """``locations`` (and ``relatedLocations`` for a DB) of one result (module doc)."""
    if f.file:
        return {"locations": [{"physicalLocation": _file_location(f.file, f.row, f.column, t, cache)}]}
    loc: dict[str, Any] = {"logicalLocations": [_logical(f)]}
    out: dict[str, Any] = {"locations": [loc]}
    if t.path is None:
        return out
    if not t.is_db:
        table_file = _table_file(t.path, f.table)
        loc["physicalLocation"] = {"artifactLocation": t.bases.location(table_file or t.path)}
        return out
    loc["physicalLocation"] = {"artifactLocation": t.bases.location(t.path)}
    source = t.source_files.get(f.table)
    if source:
        out["relatedLocations"] = [
            {
                "id": 1,
                "physicalLocation": {"artifactLocation": {"uri": source, "uriBaseId": SOURCESET}},
                "message": {"text": f"source file of table {f.table} the DB was built from"},
            }
        ]
    return out


def _uri_base(base: str) -> str:
    """``base`` ending in a slash (empty: repository-relative)."""
    return base if not base or base.endswith("/") else base + "/"


def rule_descriptor(rule: str, help_uri_base: str = "") -> dict[str, Any]:
    """The SARIF ``reportingDescriptor`` of ``rule`` from the rule catalogue (module doc); a
    rule the catalogue lacks gets its family's description only."""
    family = rule.split(".")[0]
    out: dict[str, Any] = {"id": rule, "name": rule.replace(".", "_")}
    doc = rule_catalogue().get(rule)
    if doc is None:
        out["shortDescription"] = {"text": FAMILIES.get(family, rule)}
        return out
    base = _uri_base(help_uri_base)
    out.update(
        shortDescription={"text": doc.summary},
        fullDescription={"text": doc.description},
        help={"text": doc.text(), "markdown": doc.markdown()},
        helpUri=f"{base}{RULES_DOC}#{doc.anchor}",
        properties={"tags": [family], "family": FAMILIES.get(family, family)},
    )
    if doc.severity in ("error", "warning"):
        out["defaultConfiguration"] = {"level": doc.severity}
    return out


def sarif(
    findings: Sequence[Finding],
    *,
    target: str | Path | None = None,
    tool_version: str = "0",
    help_uri_base: str = "",
    source_files: Mapping[str, str] | None = None,
    cwd: Path | None = None,
) -> dict[str, Any]:
    """The SARIF 2.1.0 log of ``findings`` (module doc). ``target`` is what was validated (a
    DB file or a source-set folder), ``source_files`` the source file a DB records per table,
    ``cwd`` the folder of ``%SRCROOT%`` (the working folder)."""
    path = Path(target).resolve() if target is not None else None
    root = None if path is None else (path if path.is_dir() else path.parent)
    bases = _Bases((cwd or Path.cwd()).resolve(), root)
    t = _Target(path, source_files or {}, bases)
    rules = sorted({f.rule for f in findings})
    index = {r: i for i, r in enumerate(rules)}
    cache: dict[str, list[str]] = {}
    results = []
    for f in findings:
        result: dict[str, Any] = {
            "ruleId": f.rule,
            "ruleIndex": index[f.rule],
            "level": "error" if f.severity == Severity.ERROR else "warning",
            "message": {"text": f"{f.where}: {f.message}"},
            **_locations(f, t, cache),
            "properties": jsonable(
                {"table": f.table, "keys": f.keys, "value": f.value, "limit": f.limit, "column": f.column}, 6
            ),
        }
        results.append(result)
    driver: dict[str, Any] = {"name": "trainpos", "version": tool_version, "semanticVersion": tool_version}
    if help_uri_base:  # an absolute URI (the schema's format): only with a base
        driver["informationUri"] = f"{_uri_base(help_uri_base)}{RULES_DOC}"
    driver["rules"] = [rule_descriptor(r, help_uri_base) for r in rules]
    used = {
        loc["physicalLocation"]["artifactLocation"].get("uriBaseId")
        for r in results
        for loc in r["locations"]
        if "physicalLocation" in loc
    }
    run: dict[str, Any] = {"tool": {"driver": driver}, "results": results}
    original = bases.original({u for u in used if u})
    if original:
        run["originalUriBaseIds"] = original
    return {"$schema": SARIF_SCHEMA, "version": "2.1.0", "runs": [run]}


def db_source_files(db: Path) -> dict[str, str]:
    """Table → the source file the DB records it was built from (meta ``source_sha256:<file>``);
    empty when the DB cannot be read (its own findings say why)."""
    from dbtools.db_info import db_info
    from schemas.errors import TrainposError

    try:
        recorded = db_info(db, verify=False).source_sha256
    except (TrainposError, OSError, sqlite3.Error):
        return {}
    return {Path(name).stem: name for name in recorded}


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
