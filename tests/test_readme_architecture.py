"""The architecture page (docs/explanation/architecture.md, once README's "Architecture"
section) stays true to the tree: every package and module it names
exists, every code name it quotes is defined in the suite, and every application package
of ``dbtools/`` and ``fieldlogs/`` is named (a new package is documented, a removed one is
not left behind). The import direction itself is checked by ``tests/test_architecture.py``."""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("cli", "dbtools", "fieldlogs", "schemas")
#: Bare ``x.py`` / ``x/`` names in the section's diagrams (other than the four packages) are
#: relative to this package (the data-flow diagram of ``trainpos run``).
DIAGRAM_BASE = "fieldlogs/pipeline"
PATH = re.compile(r"(?<![\w/.])(?:cli|dbtools|fieldlogs|schemas)(?!\w)(?:/[\w.]+)*/?")
NAME = re.compile(r"([A-Za-z_]\w*)(?:\.([A-Za-z_]\w*))?(?:\(.*\))?")
#: Diagram words that look like code names but are data: stream names, event types, placeholders.
DIAGRAM_WORDS = frozenset({"radar_if", "input_repaired", "RUN_DIR", "OUT_DIR"})
FILE_SUFFIXES = (".json", ".toml", ".csv", ".sqlite", ".html", ".parquet", ".md", ".py")


PAGE = ROOT / "docs" / "explanation" / "architecture.md"


def section() -> str:
    text = PAGE.read_text(encoding="utf-8")
    assert text.startswith("# Architecture\n"), f"{PAGE} is not the architecture page"
    return text.split("\n", 1)[1]


def _code_spans(text: str) -> list[str]:
    prose = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return re.findall(r"`([^`\n]+)`", prose)


def _diagrams(text: str) -> list[str]:
    return re.findall(r"^```text\n(.*?)^```", text, flags=re.S | re.M)


def _exists(rel: str) -> bool:
    path = ROOT / rel.rstrip("/")
    if rel.endswith(".py"):
        return path.is_file()
    return (path / "__init__.py").is_file()


def named_paths(text: str) -> set[str]:
    """Packages (``pkg/sub/``) and modules (``….py``) the section names."""
    found = {p for span in _code_spans(text) if "<" not in span for p in PATH.findall(span)}
    found = {p for p in found if p.endswith((".py", "/")) or "." not in p}
    for diagram in _diagrams(text):
        found |= set(PATH.findall(diagram))
        for rel in re.findall(r"(?<![\w/.])([a-z_]+(?:\.py|/))(?=[\s:),])", diagram):
            if rel.rstrip("/") not in PACKAGES:  # the package diagram's own boxes
                found.add(f"{DIAGRAM_BASE}/{rel}")
    return {p for p in found if p.split("/")[0] in PACKAGES and (p.endswith((".py", "/")) or "/" not in p)}


def _bound(node: ast.AST) -> set[str]:
    """Names a definition or assignment binds (one level: no tuple unpacking)."""
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
        return {node.name}
    if isinstance(node, ast.Assign):
        return {t.id for t in node.targets if isinstance(t, ast.Name)}
    if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
        return {node.target.id}
    return set()


@cache
def _definitions() -> tuple[frozenset[str], dict[str, frozenset[str]]]:
    """Every name defined anywhere in the suite, and each class's members."""
    names: set[str] = set()
    members: dict[str, set[str]] = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                names |= _bound(node)
                if isinstance(node, ast.ClassDef):
                    members.setdefault(node.name, set()).update(*(_bound(item) for item in node.body))
    return frozenset(names), {k: frozenset(v) for k, v in members.items()}


def quoted_names(text: str) -> list[tuple[str, str | None]]:
    """Code names quoted in the section's prose (``name``, ``Class.member``, ``call(args)``) and
    the names in its diagrams (snake_case with an underscore, CamelCase, UPPER_CASE)."""
    out: list[tuple[str, str | None]] = []
    for diagram in _diagrams(text):
        words = re.findall(r"(?<![\w/.{,])([a-z]+_\w+|[A-Z][a-z]+[A-Z]\w*|[A-Z]+_[A-Z_]+)(?![\w/.])", diagram)
        out += [(w, None) for w in words if w not in DIAGRAM_WORDS]
    for span in _code_spans(text):
        if span.endswith(FILE_SUFFIXES) or span.startswith(PACKAGES):
            continue
        m = NAME.fullmatch(span)
        if m:
            out.append((m.group(1), m.group(2)))
    return out


def test_every_named_package_and_module_exists() -> None:
    bare = [s for s in _code_spans(section()) if s.endswith(".py") and not s.startswith((*PACKAGES, "tests/"))]
    assert not bare, f"README's Architecture: give modules with their package path, not {bare}"
    paths = named_paths(section())
    assert len(paths) >= 40, sorted(paths)
    missing = sorted(p for p in paths if not _exists(p))
    assert not missing, f"README's Architecture names what does not exist: {missing}"


def test_every_quoted_name_is_defined() -> None:
    names, members = _definitions()
    quoted = quoted_names(section())
    assert len(quoted) >= 30, quoted
    missing = []
    for name, member in quoted:
        if name not in names:
            missing.append(name)
        elif member is not None and member not in members.get(name, frozenset()):
            missing.append(f"{name}.{member}")
    assert not missing, f"README's Architecture quotes names the code does not define: {missing}"


def test_every_application_package_is_named() -> None:
    text = section()
    named = named_paths(text)
    for pkg in ("dbtools", "fieldlogs"):
        for init in sorted((ROOT / pkg).glob("*/__init__.py")):
            sub = f"{pkg}/{init.parent.name}/"
            assert any(p == sub or p.startswith(sub) for p in named), f"README's Architecture does not name {sub}"


def test_the_section_states_the_import_direction() -> None:
    from tests.test_architecture import ALLOWED

    assert ALLOWED["cli"] >= {"dbtools", "fieldlogs", "schemas"} and ALLOWED["schemas"] == {"schemas"}
    assert "cli → dbtools, fieldlogs → schemas" in section()


def test_the_checks_catch_a_stale_section() -> None:
    stale = "`fieldlogs/nosuch/`, `dbtools/gone.py`, `NoSuchAid`, `Network.nosuch`, `run_aids`\n"
    assert {"fieldlogs/nosuch/", "dbtools/gone.py"} <= {p for p in named_paths(stale) if not _exists(p)}
    names, members = _definitions()
    quoted = quoted_names(stale)
    assert ("NoSuchAid", None) in quoted and "NoSuchAid" not in names
    assert ("Network", "nosuch") in quoted and "nosuch" not in members["Network"]
    assert "run_aids" in names
