"""One output rule for every --out (dbtools/atomic.py): an existing output is refused without
--force (exit 3), and --force never replaces an input of the same command or anything in a
release registry — for every command that writes a file or a folder."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner, Result

from cli.main import app
from dbtools.sample_network import sample_source_dir
from fieldlogs.audit.runner import audit

SAMPLE_LOGS = Path(__file__).resolve().parents[2] / "fieldlogs" / "sample_logs"
SURVEY = sample_source_dir().parent / "survey"


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


def digest(path: Path) -> str:
    """A hash of a file, or of every file below a folder (names and bytes)."""
    h = hashlib.sha256()
    for p in sorted([path] if path.is_file() else path.rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(path.parent)).encode() + p.read_bytes())
    return h.hexdigest()


@pytest.fixture(scope="module")
def world(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Copies of every input, so that a failure of the rule cannot damage the repository."""
    root = tmp_path_factory.mktemp("outputs")
    w = {"DB": root / "net.sqlite", "DB2": root / "net2.sqlite", "SRC": root / "src", "AUDIT": root / "audit.sqlite"}
    shutil.copy(sample_db, w["DB"])
    shutil.copy(sample_db, w["DB2"])
    shutil.copytree(sample_source_dir(), w["SRC"])
    for name in ("sim-d-evening", "sim-road-rail"):
        shutil.copytree(SAMPLE_LOGS / name, root / name)  # written by trainpos: they carry its marker
    w["RUN"], w["ROAD_RAIL"] = root / "sim-d-evening", root / "sim-road-rail"
    w["PLAN"] = root / "possessions.csv"
    shutil.copy(SAMPLE_LOGS / "possessions.csv", w["PLAN"])
    for name in ("centrelines.csv", "kmposts.csv"):
        shutil.copy(SURVEY / name, root / name)
    w["CL"], w["KP"] = root / "centrelines.csv", root / "kmposts.csv"
    audit([w["RUN"]], w["DB"], w["AUDIT"], workers=1)
    w["REGISTRY"] = root / "releases"
    w["REGISTRY"].mkdir()
    (w["REGISTRY"] / "registry.sqlite").write_bytes(b"")  # what makes a folder a registry
    return w


#: name → (command line with placeholders, the inputs an --out could hit, output kind)
COMMANDS: dict[str, tuple[list[str], list[str], str]] = {
    "run": (["run", "RUN", "--db", "DB", "--out", "OUT"], ["RUN"], "folder"),
    "simulate": (["simulate", "--db", "DB", "--out", "OUT", "--seed", "1"], [], "folder"),
    "possession check": (
        ["possession", "check", "ROAD_RAIL", "--db", "DB", "--plan", "PLAN", "--format", "json", "--out", "OUT"],
        ["PLAN", "DB"],
        "file",
    ),
    "gis verify --out": (["gis", "verify", "DB", "RUN", "--format", "json", "--out", "OUT", "-j", "1"], ["DB"], "file"),
    "gis verify --propose": (["gis", "verify", "DB", "RUN", "--propose", "OUT", "-j", "1"], ["RUN"], "folder"),
    "survey --out": (["survey", "RUN", "--db", "DB", "--format", "json", "--out", "OUT", "-j", "1"], ["DB"], "file"),
    "survey --propose": (["survey", "RUN", "--db", "DB", "--propose", "OUT", "-j", "1"], ["RUN"], "folder"),
    "db impact": (["db", "impact", "DB", "DB2", "RUN", "--format", "json", "--out", "OUT"], ["DB", "DB2"], "file"),
    "gnss position": (
        ["gnss", "position", "RUN", "--db", "DB", "--line", "0420", "--track", "D", "--out", "OUT"],
        ["DB"],
        "file",
    ),
    "report": (["report", "AUDIT", "--format", "json", "--out", "OUT"], ["AUDIT", "DB"], "file"),
    "db export": (["db", "export", "DB", "--format", "geojson", "--out", "OUT"], ["DB"], "file"),
    "db review": (["db", "review", "DB", "DB2", "--out", "OUT"], ["DB", "DB2"], "file"),
    "db build": (["db", "build", "SRC", "--out", "OUT", "--version", "t1"], [], "file"),
    "gis grid": (["gis", "grid", "CL", "--posts", "KP", "--out", "OUT"], ["CL", "KP"], "file"),
    "radar speed": (["radar", "speed", "RUN", "--format", "json", "--out", "OUT"], [], "file"),
}


def argv(cmd: list[str], world: dict[str, Path], out: Path) -> list[object]:
    return [out if a == "OUT" else world.get(a, a) for a in cmd]


def _existing(kind: str, path: Path) -> Path:
    if kind == "file":
        path.write_text("keep me\n", encoding="utf-8")
    else:
        path.mkdir()
        (path / "keep.txt").write_text("keep me\n", encoding="utf-8")
        (path / ".trainpos-output").write_text("", encoding="utf-8")  # even a folder trainpos wrote
    return path


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_an_existing_output_needs_force(name: str, world: dict[str, Path], tmp_path: Path) -> None:
    cmd, _, kind = COMMANDS[name]
    out = _existing(kind, tmp_path / ("out.json" if kind == "file" else "out"))
    before = digest(out)
    res = invoke(*argv(cmd, world, out))
    assert res.exit_code == 3, res.output
    assert "--force" in res.stderr and "Traceback" not in res.output
    assert digest(out) == before


@pytest.mark.parametrize(
    ("name", "target"), [(n, t) for n in sorted(COMMANDS) for t in COMMANDS[n][1]], ids=lambda x: str(x)
)
def test_force_never_replaces_an_input(name: str, target: str, world: dict[str, Path]) -> None:
    cmd, _, _ = COMMANDS[name]
    hit = world[target]
    before = digest(hit)
    res = invoke(*argv(cmd, world, hit), "--force")
    assert res.exit_code == 3, res.output
    assert "Traceback" not in res.output
    assert digest(hit) == before


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_force_never_writes_into_a_registry(name: str, world: dict[str, Path]) -> None:
    cmd, _, kind = COMMANDS[name]
    out = world["REGISTRY"] / ("2026.11.sqlite" if kind == "file" else "run")
    res = invoke(*argv(cmd, world, out), "--force")
    assert res.exit_code == 3, res.output
    assert "release registry" in " ".join(res.stderr.split())
    assert sorted(p.name for p in world["REGISTRY"].iterdir()) == ["registry.sqlite"]


DATA = Path(__file__).resolve().parents[1] / "data"


def test_import_commands_never_replace_the_folder_holding_their_source(tmp_path: Path) -> None:
    """db import / logs import --out a trainpos output folder that holds the source: refused."""
    for cmd, name, extra in (
        (["db", "import"], "railml/Track-007_28-47.railml.xml", ["--format", "railml"]),
        (["logs", "import"], "recorders/sample.nmea", ["--vehicle", DATA / "recorders" / "vehicle.toml"]),
    ):
        folder = tmp_path / cmd[0]
        folder.mkdir()
        (folder / ".trainpos-output").write_text("", encoding="utf-8")  # --force could replace it …
        source = folder / Path(name).name
        shutil.copy(DATA / name, source)  # … but it holds the input
        before = digest(folder)
        res = invoke(*cmd, source, *extra, "--out", folder, "--force")
        assert res.exit_code == 3 and ("input" in res.stderr or "source" in res.stderr), res.output
        assert digest(folder) == before
