"""The architecture holds (issue 14): imports flow cli → dbtools, fieldlogs → schemas
(fieldlogs may read through dbtools), no module over 600 lines, library code never prints."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("cli", "dbtools", "schemas", "fieldlogs")
#: What each top-level package may import of the others.
ALLOWED = {
    "schemas": {"schemas"},
    "dbtools": {"dbtools", "schemas"},
    "fieldlogs": {"fieldlogs", "dbtools", "schemas"},
    "cli": {"cli", "dbtools", "schemas", "fieldlogs"},
}
MAX_LINES = 600


def _modules() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def _imported_packages(path: Path) -> set[str]:
    """First-party top-level packages imported anywhere in the module (function-level too)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module.split(".")[0])
    return found & set(PACKAGES)


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_flow_one_way(path: Path) -> None:
    pkg = path.relative_to(ROOT).parts[0]
    bad = _imported_packages(path) - ALLOWED[pkg]
    assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)}"


def test_no_module_over_600_lines() -> None:
    long = {str(p.relative_to(ROOT)): n for p in _modules() if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, long


def test_library_code_never_prints() -> None:
    """Only the CLI renders; a module's ``main()`` (its ``python -m`` entry point) may print."""
    offenders = []
    for path in _modules():
        if path.relative_to(ROOT).parts[0] == "cli":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        scripts = {
            id(n) for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and f.name == "main" for n in ast.walk(f)
        }
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                if id(node) not in scripts:
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not offenders, offenders
