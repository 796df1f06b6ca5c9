"""The docs stay true to the code: the reference pages are generated from it and current (every
command and option, table and column, setting, finding rule), every example names real
commands and options, every link resolves, the site builds with ``--strict``, README stays
short, and nothing cites a document outside the repository."""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from cli.main import app
from cli.schema_docs import command_paths, config_keys, generated_pages

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
README = (ROOT / "README.md").read_text(encoding="utf-8")
PAGES = {p.relative_to(ROOT).as_posix(): p.read_text(encoding="utf-8") for p in sorted(DOCS.rglob("*.md"))}
ALL = {"README.md": README, **PAGES}
COMMANDS_PAGE = PAGES["docs/reference/commands.md"]
ROOT_CMD = typer.main.get_command(app)
COMMANDS = dict(command_paths(ROOT_CMD))


def _is_group(cmd: object) -> bool:
    return hasattr(cmd, "commands")  # typer's click groups (typer may vendor its own click)


# --- the generated reference is current and complete -------------------------------------


@pytest.mark.parametrize("path", sorted(p.relative_to(ROOT).as_posix() for p in generated_pages()))
def test_generated_pages_are_current(path: str) -> None:
    want = generated_pages()[ROOT / path]
    assert (ROOT / path).read_text(encoding="utf-8") == want, f"{path} is stale: run python -m cli.schema_docs"


@pytest.mark.parametrize("path", sorted(COMMANDS), ids=" ".join)
def test_every_command_and_option_is_documented(path: tuple[str, ...]) -> None:
    cmd = COMMANDS[path]
    name = f"trainpos {' '.join(path)}"
    assert (cmd.help or "").strip(), f"`{name}` has no help text"
    assert f"## `{name}`" in COMMANDS_PAGE, f"docs/reference/commands.md does not document `{name}`"
    section = COMMANDS_PAGE.split(f"## `{name}`", 1)[1].split("\n## ", 1)[0]
    for p in cmd.params:
        for opt in (*p.opts, *p.secondary_opts):
            if opt.startswith("-") and opt != "--help":
                assert f"`{opt}`" in section, f"`{name} {opt}` is undocumented"
        assert p.param_type_name != "option" or (p.help or "").strip(), f"`{name} {p.opts[0]}` has no help"


def test_every_setting_is_documented() -> None:
    page = PAGES["docs/reference/config.md"]
    keys = config_keys()
    assert len(keys) >= 50
    for section, key in keys:
        assert f"`{key}`" in (page.split(f"## `[{section}]`", 1)[1] if section else page), (section, key)


def test_every_finding_rule_is_documented() -> None:
    """Every rule of the catalogue (which tests/dbtools/rules/test_rule_catalogue.py holds to every
    rule id the code emits) has its row, meaning, fix and anchor — the SARIF helpUri — in rules.md."""
    from dbtools.interchange.ci import RULES_DOC
    from dbtools.rules.catalogue import rule_catalogue

    catalogue = rule_catalogue()
    assert len(catalogue) >= 80 and RULES_DOC == "docs/reference/rules.md"
    page = PAGES[RULES_DOC]
    for rid, rule in catalogue.items():
        assert f'<a id="{rule.anchor}"></a>`{rid}`' in page, rid
        assert rule.meaning.strip() and rule.fix.strip(), rid


def test_every_table_and_column_is_documented() -> None:
    from schemas.catalog import ALL_SCHEMAS

    page = PAGES["docs/reference/schemas.md"]
    for t in ALL_SCHEMAS.values():
        assert f"**{t.name}** ({t.kind})" in page, t.name
        section = page.split(f"**{t.name}** ({t.kind})", 1)[1].split("\n**", 1)[0]
        for c in t.columns:
            assert f"| `{c.name}` | {c.dtype} | {c.unit} |" in section, (t.name, c.name)


def test_exit_codes_documented() -> None:
    page = PAGES["docs/reference/behaviour.md"]
    for code in ("| 0 |", "| 1 |", "| 2 |", "| 3 |", "| 4 |"):
        assert code in page


def test_help_runs_for_every_command_and_keeps_units() -> None:
    runner = CliRunner()
    for path, cmd in COMMANDS.items():
        result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "400"})
        assert result.exit_code == 0, (path, result.output)
        flat = " ".join(result.output.split())
        for p in cmd.params:
            for unit in re.findall(r"\[[^\]]+\]", getattr(p, "help", None) or ""):
                assert unit in flat, f"`trainpos {' '.join(path)} --help` lost {unit} (rich markup?)"


# --- examples ----------------------------------------------------------------------------


def _invocations(text: str) -> list[list[str]]:
    """Every `trainpos …` line of a page's ```sh blocks (continuations joined)."""
    calls = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = re.split(r"\s(?:\|\||&&|\||;)\s", line.split("#")[0])[0].strip()  # the command, not `|| …`
            if line.startswith("trainpos "):
                calls.append(shlex.split(line)[1:])
    return calls


def test_examples_name_real_commands_and_options() -> None:
    calls = [(page, argv) for page, text in ALL.items() for argv in _invocations(text)]
    assert len(calls) >= 60
    helps = re.findall(r"^\$ trainpos (.*)$", COMMANDS_PAGE, flags=re.M)  # every --help's example
    assert len(helps) >= len(COMMANDS) - 2
    calls += [("trainpos --help example", shlex.split(line.split(" > ")[0])) for line in helps]
    for page, argv in calls:
        group: Any = ROOT_CMD
        path: list[str] = []
        while _is_group(group) and argv and argv[0] in group.commands:
            path.append(argv[0])
            group = group.commands[argv.pop(0)]
        assert not _is_group(group), f"{page}: `trainpos {' '.join(path)}` is not a command"
        known = {o for p in group.params for o in (*p.opts, *p.secondary_opts)}
        for token in argv:
            if token.startswith("-"):
                assert token.split("=")[0] in known, f"{page}: `trainpos {' '.join(path)}` has no option {token}"


# --- links, size, citations --------------------------------------------------------------

LINK = re.compile(r"(?<!!)\[[^\]\n]*\]\(([^)\s]+)\)")


def _anchors(text: str) -> set[str]:
    """The anchors of a page: explicit ``<a id>`` and MkDocs' heading slugs."""
    found = set(re.findall(r'<a id="([^"]+)"', text))
    for title in re.findall(r"^#{1,6} (.+)$", re.sub(r"^```.*?^```", "", text, flags=re.S | re.M), flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", title.lower().replace("`", "")).strip()
        found.add(re.sub(r"[\s]+", "-", slug))
    return found


@pytest.mark.parametrize("page", sorted(ALL))
def test_links_resolve(page: str) -> None:
    base = (ROOT / page).parent
    for target in LINK.findall(re.sub(r"^```.*?^```", "", ALL[page], flags=re.S | re.M)):
        if re.match(r"[a-z]+:", target):
            continue  # an external address
        path, _, anchor = target.partition("#")
        dest = (base / path).resolve() if path else (ROOT / page)
        assert dest.is_file(), f"{page}: dead link {target}"
        assert ROOT in dest.parents, f"{page}: {target} leads out of the repository"
        if page.startswith("docs/"):
            assert DOCS in dest.parents, f"{page}: {target} is not a docs page (the site cannot link it)"
        if anchor and dest.suffix == ".md":
            assert anchor in _anchors(dest.read_text(encoding="utf-8")), f"{page}: no anchor #{anchor} in {path}"


def test_the_dead_link_check_catches_one(tmp_path: Path) -> None:
    text = "see [gone](nosuch.md) and [fine](docs/index.md#tutorials)"
    targets = LINK.findall(text)
    assert targets == ["nosuch.md", "docs/index.md#tutorials"]
    assert not (ROOT / "nosuch.md").exists()
    assert "tutorials" in _anchors(PAGES["docs/index.md"])


def test_readme_is_short_and_links_the_guide() -> None:
    assert len(README.encode("utf-8")) <= 15_000, len(README.encode("utf-8"))
    for part in ("docs/tutorials/", "docs/reference/commands.md", "docs/explanation/papers.md"):
        assert part in README


def test_nothing_cites_documents_outside_the_repository() -> None:
    for page, text in ALL.items():
        for bad in ("SPEC §", "SPEC's", "/work/", "../shared", "as the papers report them"):
            assert bad not in text, f"{page} cites {bad!r}: not in the repository"
        keys = re.findall(r"\bS00\d\b", text) if page != "docs/explanation/papers.md" else []
        assert not keys, f"{page}: cite the papers by author (docs/explanation/papers.md), not {keys}"


def test_every_docs_page_is_in_the_site_nav() -> None:
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for page in PAGES:
        assert page.removeprefix("docs/") in nav, f"{page} is not in mkdocs.yml's nav"


def test_the_site_builds_strict(tmp_path: Path) -> None:
    """`make docs`: mkdocs --strict fails on a dead link, a missing anchor or a page off the nav."""
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent))
    if mkdocs is None:
        pytest.skip("mkdocs is not installed (pip install -e '.[dev]')")
    res = subprocess.run(
        [mkdocs, "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    assert (tmp_path / "site" / "reference" / "rules.html").is_file()


def test_the_report_summary_explains_every_term() -> None:
    """`make demo` / `trainpos demo` prints the report tables and one line per term they use."""
    from cli.audit import LEGEND, OTHER_COLUMNS, PCT_COLUMNS
    from schemas.labels import label

    explained = {t.strip() for key in LEGEND for t in key.split(",")}
    shown = [label(c) for c in (*PCT_COLUMNS, *OTHER_COLUMNS, "refusal_reasons")]
    assert not [s for s in shown if s not in explained], "report columns without a line in cli/audit.py LEGEND"
    assert all(len(line) <= 100 for line in LEGEND.values())
