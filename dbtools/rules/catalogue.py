"""The rule catalogue: every finding's rule id with its severity, meaning and fix, parsed from
the module docstrings that document the rules where they are checked.

A rule is documented in the docstring of the module that emits it (``dbtools/**``,
``schemas/**``) by a bullet of the form::

    * ``family.name`` (error) — what is wrong. Fix: what to change.

— the severity in parentheses may be ``warning``, ``error``, ``warning / error`` or left out
(a rule whose severity depends on the table), the meaning runs from the dash to ``Fix:``, the
fix to the end of the bullet (continuation lines are indented). A rule documented in two
modules (``schema.range``: the declared ranges and the operating area) gets both texts.

:func:`rule_catalogue` is the one source for the SARIF rule descriptors
(:mod:`dbtools.interchange.ci`) and the rule reference of the documentation
(``docs/reference/rules.md``, one anchor per rule id). The sources are read as text (no
import), so the catalogue costs one parse of the package's docstrings.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from functools import cache
from pathlib import Path

#: The rule families and what each covers (the SARIF and docs group headings).
FAMILIES = {
    "schema": "Source and table schema: types, required values, enumerations, ranges, keys",
    "source": "Source set files and line codes",
    "gis": "GIS grid: 20 m steps, breaks, spacing, spikes, area, heights",
    "balise": "Balises: initial pairs, C balises, ETCS balise groups, identification windows, GIS range",
    "topology": "Network topology: track/switch references, switch ports and routes, connection gaps, km, lengths, "
    "crossover angles, open ends, balise identification along routes",
    "feature": "Feature points: rows, radius and direction against the GIS curvature, straights",
    "db": "DB file: SQLite integrity, foreign keys, meta and content hash",
    "railml": "railML import",
}

#: A rule id: a family and a lower-case name.
RULE_ID = re.compile(rf"^(?:{'|'.join(FAMILIES)})\.[a-z][a-z0-9_]*$")

_BULLET = re.compile(
    rf"^\*\s+``(?P<id>(?:{'|'.join(FAMILIES)})\.[a-z][a-z0-9_]*)``\s*"
    r"(?:\((?P<sev>[a-z /]+)\))?\s*[—–-]+\s*(?P<text>.*)$"
)

#: The roots whose modules' docstrings are read.
ROOTS = ("dbtools", "schemas")


@dataclass(frozen=True)
class RuleDoc:
    """One rule: id, severity as documented (``error``, ``warning``, ``warning / error`` or
    ``""`` when it depends on the table), what it means, how to fix it, where it is documented."""

    id: str
    severity: str
    meaning: str
    fix: str
    modules: tuple[str, ...]

    @property
    def family(self) -> str:
        """The part of the id before the dot (``balise``, ``topology`` …)."""
        return self.id.split(".", 1)[0]

    @property
    def anchor(self) -> str:
        """The URL fragment of the rule in the rule reference: the id itself (the reference
        gives every rule an ``<a id="family.name">`` anchor)."""
        return self.id

    @property
    def summary(self) -> str:
        """The meaning's first sentence or clause (outside parentheses, at least a few words),
        as plain text: a title. Capitalised unless it starts with a name in backquotes."""
        return self._capital(_first_clause(plain(self.meaning)))

    @property
    def description(self) -> str:
        """The whole meaning as plain text, capitalised like :attr:`summary`."""
        return self._capital(plain(self.meaning))

    def _capital(self, text: str) -> str:
        return text if markdown(self.meaning).startswith("`") else text[:1].upper() + text[1:]

    def text(self) -> str:
        """Meaning and fix as plain text."""
        return f"{self.description} Fix: {plain(self.fix)}"

    def markdown(self) -> str:
        """The help text in Markdown: id, severity, meaning and fix."""
        sev = f" ({self.severity})" if self.severity else ""
        return f"**{self.id}**{sev}: {markdown(self.meaning)}\n\n**Fix:** {markdown(self.fix)}"


_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def markdown(rst: str) -> str:
    """Docstring markup as Markdown: ````x```` and Sphinx roles (``:mod:`x```) become ```x```."""
    return _ROLE.sub(r"`\1`", rst).replace("``", "`")


def _first_clause(text: str, min_chars: int = 20) -> str:
    """``text`` up to the first ". ", ": " or "; " outside parentheses after ``min_chars``."""
    depth = 0
    for i, ch in enumerate(text):
        depth += (ch in "([") - (ch in ")]")
        if depth == 0 and i >= min_chars and ch in ".:;" and text[i + 1 : i + 2] in (" ", ""):
            return text[:i]
    return text.rstrip(".:;")


def plain(rst: str) -> str:
    """Docstring markup as plain text (no backquotes)."""
    return markdown(rst).replace("`", "")


def _bullets(doc: str) -> list[tuple[str, str, str]]:
    """(id, severity, text) of every rule bullet of one docstring, continuation lines joined."""
    out: list[tuple[str, str, list[str]]] = []
    open_bullet = False
    for line in doc.splitlines():
        m = _BULLET.match(line.strip())
        if m:
            out.append((m["id"], (m["sev"] or "").strip(), [m["text"]]))
            open_bullet = True
        elif open_bullet and line.startswith(" ") and line.strip():
            out[-1][2].append(line.strip())
        else:
            open_bullet = False
    return [(rule, sev, " ".join(text)) for rule, sev, text in out]


def parse_docstring(doc: str) -> list[tuple[str, str, str, str]]:
    """(id, severity, meaning, fix) of every rule bullet of ``doc`` (module doc)."""
    out = []
    for rule, sev, text in _bullets(doc):
        meaning, _, fix = text.partition("Fix:")
        out.append((rule, sev, meaning.strip(), fix.strip()))
    return out


def _sources(root: Path) -> list[Path]:
    return sorted(p for name in ROOTS for p in (root / name).rglob("*.py"))


def module_name(path: Path, root: Path) -> str:
    """``dbtools/rules/gis.py`` → ``dbtools.rules.gis``."""
    return ".".join(path.relative_to(root).with_suffix("").parts)


def catalogue_from(root: Path) -> dict[str, RuleDoc]:
    """The catalogue of the packages under ``root`` (the repository), sorted by id."""
    found: dict[str, list[tuple[str, str, str, str]]] = {}
    for path in _sources(root):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")))
        for rule, sev, meaning, fix in parse_docstring(doc or ""):
            found.setdefault(rule, []).append((module_name(path, root), sev, meaning, fix))
    out: dict[str, RuleDoc] = {}
    for rule in sorted(found):
        parts = found[rule]
        sevs = sorted({p[1] for p in parts if p[1]})
        out[rule] = RuleDoc(
            id=rule,
            severity=" / ".join(sevs) if len(sevs) > 1 else (sevs[0] if sevs else ""),
            meaning=" ".join(p[2] for p in parts if p[2]),
            fix=" ".join(p[3] for p in parts if p[3]),
            modules=tuple(p[0] for p in parts),
        )
    return out


@cache
def _catalogue() -> dict[str, RuleDoc]:
    return catalogue_from(Path(__file__).resolve().parents[2])


def rule_catalogue() -> dict[str, RuleDoc]:
    """Every documented rule id → its :class:`RuleDoc`, sorted by id (module doc); the
    docstrings are parsed once, each call gets its own dict."""
    return dict(_catalogue())
