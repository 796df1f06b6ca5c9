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

from tests.fresh import fresh_python

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
    data: dict[str, object] = json.loads(fresh_python(PROBE))
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
    assert fresh_python(code).split() == ["True", "True"]


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


#: Not imported by ``trainpos run`` of a recorded run (a few thousand GPS fixes): the map
#: matching takes its numpy path, the DB is read without pandera or sqlite_utils, typer
#: coerces the command's paths without pydantic (bench/NOTES.md, issue 21 third pass).
NOT_FOR_A_RUN = ("numba", "llvmlite", "scipy", "pandera", "pydantic", "sqlite_utils", "dask", "matplotlib")


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_run_of_a_recorded_run_imports_neither_numba_nor_the_checkers(
    fmt: str, sample_db: Path, tmp_path: Path
) -> None:
    """The real entry point's ``run`` command on a sample run (Parquet as shipped, and the
    same run written as CSV), in a fresh interpreter: positions written, none of
    :data:`NOT_FOR_A_RUN` imported."""
    run_dir = ROOT / "fieldlogs" / "sample_logs" / "sim-d-evening"
    if fmt == "csv":
        from fieldlogs.runs.handle import read_run
        from fieldlogs.runs.write import write_run

        run = read_run(run_dir)
        streams = {p.stem: run.stream(p.stem) for p in run_dir.glob("*.parquet")}
        run_dir = write_run(tmp_path / "csv-run", run.meta, streams, fmt="csv")
    code = (
        "import json, sys\nfrom cli.main import app\n"
        "try:\n    app(sys.argv[1:])\nexcept SystemExit as exc:\n    assert not exc.code, exc.code\n"
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))\n"
    )
    out = tmp_path / "out"
    args = ["run", str(run_dir), "--db", str(sample_db), "--out", str(out)]
    stdout = fresh_python(code, *args)
    assert (out / "positions.csv").stat().st_size > 1000
    imported = set(json.loads(stdout.strip().splitlines()[-1]))
    assert {"pandas", "pyarrow", "rich"} <= imported  # the probe sees the run's real imports
    assert sorted(imported & set(NOT_FOR_A_RUN)) == []


def test_run_command_parses_paths_as_typer_does() -> None:
    """cli.main.PathCommand (plain Path parameters coerced without pydantic) gives the same
    parameters as typer's own command, and the same usage error for a missing option."""
    import typer
    from typer.core import TyperCommand

    import cli.main
    from cli.run import run as run_fn

    ours = typer.main.get_command(cli.main.app).commands["run"]
    assert isinstance(ours, cli.main.PathCommand)
    plain = typer.Typer()
    plain.command("run", cls=TyperCommand)(run_fn)
    plain.command("other", cls=TyperCommand)(run_fn)  # two commands: a group, as the real app
    theirs = typer.main.get_command(plain).commands["run"]
    for args in (
        ["logs/r1", "--db", "net.sqlite", "--out", "o"],
        ["logs/r1", "--db", "./a b/ü.sqlite", "-o", "/tmp/x/", "--config", "c.toml", "--force", "--no-verify-hash"],
        ["-", "--db", "-", "--out", "~/x"],
    ):
        a = ours.make_context("run", list(args)).params
        b = theirs.make_context("run", list(args)).params
        assert a == b and all(type(a[k]) is type(b[k]) for k in a), (args, a, b)
        assert isinstance(a["run_dir"], Path)
    with pytest.raises(typer._click.exceptions.MissingParameter) as mine:
        ours.make_context("run", ["logs/r1", "--out", "o"])
    with pytest.raises(typer._click.exceptions.MissingParameter) as typers:
        theirs.make_context("run", ["logs/r1", "--out", "o"])
    assert str(mine.value) == str(typers.value)


def test_validate_command_parses_as_typer_does() -> None:
    """``db validate`` is a cli.commands.PathCommand: its Path, str and Enum parameters give
    the values typer's own (pydantic) coercion gives, of the same types, and a value outside
    the enumeration the same error (hand-made: click's Choice never lets one through)."""
    import typer
    from typer.core import TyperCommand

    import cli.main
    from cli.commands import _PlainChoice
    from cli.db import ValidateFmt
    from cli.db import validate as validate_fn

    ours = typer.main.get_command(cli.main.app).commands["db"].commands["validate"]
    assert isinstance(ours, cli.main.PathCommand)
    plain = typer.Typer()
    plain.command("validate", cls=TyperCommand)(validate_fn)
    plain.command("other", cls=TyperCommand)(validate_fn)
    theirs = typer.main.get_command(plain).commands["validate"]
    for args in (
        ["net.sqlite"],
        ["./a b/ü", "--format", "json", "--strict"],
        ["x.sqlite", "--format", "sarif", "--help-uri-base", "https://x/", "--delimiter", ";", "--decimal", ","],
        ["-", "--format", "junit"],
    ):
        a = ours.make_context("validate", list(args)).params
        b = theirs.make_context("validate", list(args)).params
        assert a == b and all(type(a[k]) is type(b[k]) for k in a), (args, a, b)
        assert isinstance(a["target"], Path) and isinstance(a["fmt"], ValidateFmt)
    param = next(p for p in ours.params if p.name == "fmt")
    ctx = ours.make_context("validate", ["x"])
    with pytest.raises(typer._click.exceptions.BadParameter) as mine:
        _PlainChoice(param.type_descriptor.parameter_info, ValidateFmt).coerce("xml", param, ctx)
    with pytest.raises(typer._click.exceptions.BadParameter) as typers:
        typer._coercion.build_runtime_param(param.type_descriptor).coerce("xml", param, ctx)
    assert str(mine.value) == str(typers.value) and "is not one of" in str(mine.value)


def test_validate_of_a_db_imports_no_pydantic(sample_db: Path) -> None:
    """``trainpos db validate`` through the real entry point, in a fresh interpreter: the
    findings printed, pydantic (typer's coercion, 0.1 s of start-up) not imported, and numpy
    imported with its huge-page advice off (cli.commands.small_pages)."""
    code = (
        "import json, os, sys\nos.environ.pop('NUMPY_MADVISE_HUGEPAGE', None)\nfrom cli.main import app\n"
        "try:\n    app(sys.argv[1:])\nexcept SystemExit as exc:\n    assert exc.code in (0, 1), exc.code\n"
        "from numpy._core.multiarray import _get_madvise_hugepage\n"
        "print(json.dumps([_get_madvise_hugepage(), sorted({m.split('.')[0] for m in sys.modules})]))\n"
    )
    stdout = fresh_python(code, "db", "validate", str(sample_db), "--format", "json")
    assert '"findings"' in stdout
    hugepage, imported = json.loads(stdout.strip().splitlines()[-1])
    assert "pandas" in imported and "pydantic" not in imported
    assert hugepage is False
