"""The CLI starts light (issue 21): importing ``cli.main`` and printing any command's
``--help`` import none of the heavy libraries, which only the commands that need them
import, inside the functions that use them. The wall-time target (≤ 0.3 s) is measured by
``bench/bench_startup.py``, not here."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Never imported by ``import cli.main`` nor by any ``--help``: everything that costs start-up
#: time (numpy and pandas too: ``--help`` needs neither), and rich and pydantic for ``--help``.
HEAVY = (
    "dask",
    "distributed",
    "numba",
    "llvmlite",
    "matplotlib",
    "scipy",
    "pandera",
    "pyarrow",
    "pyproj",
    "shapely",
    "pandas",
    "numpy",
)
HELP_TOO = ("rich", "pydantic")

#: Run in a fresh interpreter: every command's --help through typer's CliRunner, then what
#: was imported (the test process itself has imported everything long before).
PROBE = """
import json, sys
import typer
from typer.testing import CliRunner

import cli.main

after_import = sorted(sys.modules)
root = typer.main.get_command(cli.main.app)


def paths(cmd, prefix=()):
    yield prefix
    for name, sub in getattr(cmd, "commands", {}).items():
        yield from paths(sub, (*prefix, name))


runner = CliRunner()
helps = {}
for path in paths(root):
    res = runner.invoke(cli.main.app, [*path, "--help"], env={"COLUMNS": "120"})
    helps[" ".join(path)] = [res.exit_code, res.output]
json.dump({"after_import": after_import, "after_help": sorted(sys.modules), "helps": helps}, sys.stdout)
"""


def _top(modules: list[str], names: tuple[str, ...]) -> list[str]:
    return sorted({m.split(".")[0] for m in modules} & set(names))


@pytest.fixture(scope="module")
def probe() -> dict[str, object]:
    proc = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=ROOT, capture_output=True, text=True, check=False, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    data: dict[str, object] = json.loads(proc.stdout)
    return data


def test_import_of_cli_main_imports_no_heavy_library(probe: dict[str, list[str]]) -> None:
    assert _top(probe["after_import"], HEAVY + HELP_TOO) == []


def test_help_of_every_command_imports_no_heavy_library(probe: dict[str, list[str]]) -> None:
    assert _top(probe["after_help"], HEAVY + HELP_TOO) == []


def test_help_of_every_command_works(probe: dict[str, dict[str, list[object]]]) -> None:
    helps = probe["helps"]
    # the root, every group and every command (test_docs.py checks each one's text)
    assert {"", "db", "db build", "gis verify", "logs import", "report", "demo"} <= set(helps)
    for path, (code, output) in helps.items():
        assert code == 0, (path, output)
        assert str(output).startswith(f"Usage: trainpos {path}".rstrip()), (path, output)
        assert "--help" in str(output), path


def test_a_command_still_imports_what_it_needs() -> None:
    """The lazy imports are real imports: a command that needs the pipeline's libraries gets
    them (``config show`` reads the settings only: no numpy; ``schema show`` with a
    misspelled name reaches pandas for the suggestion)."""
    code = (
        "import sys\nfrom typer.testing import CliRunner\nimport cli.main\n"
        "r = CliRunner().invoke(cli.main.app, ['config', 'show', '--section', 'gps'])\n"
        "assert r.exit_code == 0 and '[gps]' in r.output, r.output\n"
        "light = 'numpy' not in sys.modules\n"
        "r = CliRunner().invoke(cli.main.app, ['schema', 'show', 'gsi'])\n"
        "assert r.exit_code == 2 and \"did you mean 'gps'\" in r.output, r.output\n"
        "print(light, 'pandas' in sys.modules)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["True", "True"]


def test_errors_still_map_to_exit_codes(tmp_path: Path) -> None:
    """cli/errors.py with lazy imports, through the installed entry point: a typed InputError
    (a config file that does not exist) exits 2, a RefusedError (output exists) exits 3, each
    one line on stderr, never a traceback."""
    trainpos = str(Path(sys.executable).parent / "trainpos")
    exists = tmp_path / "impact.json"
    exists.write_bytes(b"")
    for args, code in (
        (["config", "show", "--config", str(tmp_path / "missing.toml")], 2),
        (["db", "impact", "old.sqlite", "new.sqlite", "logs/", "--out", str(exists)], 3),
    ):
        proc = subprocess.run([trainpos, *args], cwd=tmp_path, capture_output=True, text=True, check=False)
        assert proc.returncode == code, (args, proc.stderr)
        assert proc.stderr.startswith("error: ") and "Traceback" not in proc.stderr, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert exists.read_bytes() == b""  # never touched
