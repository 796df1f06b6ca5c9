"""XML Schema validation of railML against a schema the user supplies (``--xsd``).

The railML XSDs are not shipped with the suite (their licence), so ``db export --format
railml`` and ``db import --format railml`` validate only when given one: ``--xsd
PATH/railml3.xsd`` (the schema's ``xs:include``/``xs:import`` files must be beside it or
wherever its ``schemaLocation`` says, on disk: nothing is fetched from the network).
Validation is lxml's (libxml2's XML Schema 1.0); every schema error becomes a finding with
the element's path and line and the schema's own reason.

An XSD that cannot be read or is not a valid schema is an :class:`InputError` (exit 2);
a document the schema rejects is a :class:`FindingsError` (exit 1) and nothing is written.

* ``railml.xsd`` (error) — the railML document is not valid against the given XML Schema
  (the message has the element's path, line and the schema's reason). Fix: correct the
  element in the file (or, for an export, report it: the writer must produce valid railML).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from schemas.enums import Severity
from schemas.errors import FindingsError, InputError
from schemas.findings import Finding

RULE = "railml.xsd"


def load_schema(path: Path) -> Any:
    """The ``lxml.etree.XMLSchema`` of ``path``; InputError naming file, line and reason
    when it is missing, not XML or not a valid schema."""
    from lxml import etree

    path = Path(path)
    if not path.is_file():
        raise InputError("XML Schema: " + ("no such file" if not path.exists() else "not a file"), path=path)
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False)
    try:
        doc = etree.parse(str(path), parser)
    except etree.XMLSyntaxError as exc:
        raise InputError(f"XML Schema: malformed XML: {exc.msg}", path=path, row=_line(exc.lineno)) from exc
    try:
        return etree.XMLSchema(doc)
    except etree.XMLSchemaParseError as exc:
        err = exc.error_log.last_error if len(exc.error_log) else None
        where = Path(err.filename) if err is not None and err.filename else path
        reason = err.message if err is not None else str(exc)
        raise InputError(
            f"not a usable XML Schema: {reason}", path=where, row=_line(err.line if err else None)
        ) from exc


def _line(value: Any) -> int | None:
    return value if isinstance(value, int) and value > 0 else None


def schema_findings(schema: Any, tree: Any, *, file: str, xsd: Path) -> list[Finding]:
    """One error finding per schema violation of ``tree`` (element path and line)."""
    if schema.validate(tree):
        return []
    out = []
    for err in schema.error_log:
        keys = {"element": _element_path(tree, err.path)} if err.path else {}
        message = f"not valid against {Path(xsd).name}: {err.message}"
        out.append(Finding(RULE, Severity.ERROR, "railml", message, keys=keys, file=file, row=_line(err.line)))
    return out


def _element_path(tree: Any, xpath: str) -> str:
    """libxml2's path (``/*/*[2]/*`` for namespaced elements) as local names
    (``/railML/infrastructure/…``, :func:`~dbtools.interchange.xmltree.path_of`)."""
    from lxml import etree

    from dbtools.interchange.xmltree import path_of

    try:
        found = tree.xpath(xpath)
    except etree.XPathError:
        return xpath
    return path_of(found[0]) if isinstance(found, list) and len(found) == 1 else xpath


def check_valid(schema: Any, tree: Any, *, file: str, xsd: Path, what: str) -> None:
    """FindingsError (nothing written) when ``tree`` is not valid against ``schema``; the
    message gives the first error's line and reason and the count."""
    findings = schema_findings(schema, tree, file=file, xsd=xsd)
    if findings:
        first = findings[0]
        reason = first.message.split(": ", 1)[1]
        raise FindingsError(
            f"{what} is not valid against {Path(xsd).name}: {reason} "
            f"({len(findings)} schema error(s); nothing was written)",
            findings,
            path=file,
            row=first.row,
        )
