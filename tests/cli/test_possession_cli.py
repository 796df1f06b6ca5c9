"""``trainpos possession check``: formats, exit codes and messages (on simulated runs)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.gis.geometry import Projector
from dbtools.sources import write_source_set
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.possession import make_case


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("possession")
    net = build_network([demo_line()], Projector(9))
    write_source_set(net, root / "src")
    build_db(root / "src", root / "net.sqlite", db_version="2026.01-test")
    out = {"db": root / "net.sqlite", "root": root}
    for kind, seed in (("correct", 11), ("overrun", 31), ("wrong_track", 21)):
        run, plan = make_case(net, kind, seed).write(root, fmt="csv")
        out[kind], out[f"{kind}_plan"] = run, plan
    return out


def invoke(*args: object) -> object:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "250"})


def test_correct_run_exits_0(world: dict[str, Path]) -> None:
    res = invoke("possession", "check", world["correct"], "--db", world["db"], "--plan", world["correct_plan"])
    assert res.exit_code == 0, res.output
    assert "0 alarm(s) in 1 run(s)" in res.stdout
    assert "track decision" in res.stdout


def test_overrun_json_shape_and_exit_1(world: dict[str, Path], tmp_path: Path) -> None:
    res = invoke(
        "possession",
        "check",
        world["overrun"],
        "--db",
        world["db"],
        "--plan",
        world["overrun_plan"],
        "--format",
        "json",
    )
    assert res.exit_code == 1, res.output
    data = json.loads(res.stdout)
    (run,) = data["runs"]
    assert set(run) >= {"run", "run_id", "possessions", "track_decision", "alarms", "notices"}
    assert run["run_id"] == "PZ-overrun-31" and run["possessions"] == ["W00031"]
    assert set(run["track_decision"]) >= {"t", "time", "line_code", "track", "evidence"}
    (alarm,) = run["alarms"]
    assert set(alarm) == {"type", "t", "time", "km_m", "track", "work_no", "evidence"}
    assert alarm["type"] == "overrun" and alarm["work_no"] == "W00031" and alarm["time"].endswith("+09:00")
    assert any(n["type"] == "approaching_end" for n in run["notices"])
    out = tmp_path / "r.json"
    res = invoke(
        "possession",
        "check",
        world["overrun"],
        world["correct"],
        "--db",
        world["db"],
        "--plan",
        world["overrun_plan"],
        "--format",
        "json",
        "--out",
        out,
    )
    assert res.exit_code == 1
    assert [r["run_id"] for r in json.loads(out.read_text(encoding="utf-8"))["runs"]] == [
        "PZ-overrun-31",
        "PZ-correct-11",
    ]


def test_wrong_track_table_and_html(world: dict[str, Path], tmp_path: Path) -> None:
    args = ("possession", "check", world["wrong_track"], "--db", world["db"], "--plan", world["wrong_track_plan"])
    res = invoke(*args)
    assert res.exit_code == 1
    assert "wrong_track" in res.stdout
    out = tmp_path / "pz.html"
    res = invoke(*args, "--format", "html", "--out", out)
    assert res.exit_code == 1, res.output
    text = out.read_text(encoding="utf-8")
    assert "data:image/png;base64," in text and "wrong_track" in text and "<script" not in text
    res = invoke(*args, "--format", "html")
    assert res.exit_code == 2 and "--out" in res.stderr


def test_plan_errors_exit_1_with_file_line_column(world: dict[str, Path], tmp_path: Path) -> None:
    plan = tmp_path / "bad.csv"
    lines = world["correct_plan"].read_text(encoding="utf-8").splitlines()
    lines[1] = lines[1].replace("+09:00", "", 1)
    plan.write_text("\n".join(lines) + "\n", encoding="utf-8")
    res = invoke("possession", "check", world["correct"], "--db", world["db"], "--plan", plan)
    assert res.exit_code == 1
    err = " ".join(res.stderr.split())
    assert "plan.time_offset" in err and "bad.csv:2" in err and "planned_start" in err


@pytest.mark.parametrize("what", ["plan", "db", "run"])
def test_unreadable_inputs_exit_2(world: dict[str, Path], tmp_path: Path, what: str) -> None:
    args = {"run": world["correct"], "db": world["db"], "plan": world["correct_plan"]}
    args[what] = tmp_path / "missing"
    res = invoke("possession", "check", args["run"], "--db", args["db"], "--plan", args["plan"])
    assert res.exit_code == 2, res.output
    assert "missing" in res.stderr


def test_run_without_offset_in_start_time_exits_2(world: dict[str, Path], tmp_path: Path) -> None:
    import shutil

    run = tmp_path / "run"
    shutil.copytree(world["correct"], run)
    meta = json.loads((run / "run.json").read_text(encoding="utf-8"))
    meta["start_time"] = meta["start_time"][:19]
    (run / "run.json").write_text(json.dumps(meta), encoding="utf-8")
    res = invoke("possession", "check", run, "--db", world["db"], "--plan", world["correct_plan"])
    assert res.exit_code == 2
    assert "UTC offset" in res.stderr


def test_help() -> None:
    res = invoke("possession", "check", "--help")
    assert res.exit_code == 0
    assert "Exit codes" in res.stdout and "--plan" in res.stdout


def test_tacho_used_when_present_and_reported_when_bad(world: dict[str, Path], tmp_path: Path) -> None:
    """PZ-correct-20085 stops ~30 m before the section end in poor sky: a false overrun with
    GPS only, none with its tacho; a decreasing pulse count (a counter reset) is not used,
    and the output says so — the check is then the GPS-only one (exit 1 again)."""
    net = build_network([demo_line()], Projector(9))
    run, plan = make_case(net, "correct", 20085, poor_sky=True, tacho=True).write(tmp_path, fmt="csv")
    args = ("possession", "check", run, "--db", world["db"], "--plan", plan, "--format", "json")
    res = invoke(*args)
    assert res.exit_code == 0, res.output
    (data,) = json.loads(res.stdout)["runs"]
    assert data["tacho"] == {"used": True, "note": None} and data["alarms"] == []
    tacho = run / "tacho.csv"
    lines = tacho.read_text(encoding="utf-8").splitlines()
    t, _ = lines[2001].split(",")
    lines[2001] = f"{t},5"  # row 2002: the counter jumps back
    tacho.write_text("\n".join(lines) + "\n", encoding="utf-8")
    res = invoke(*args)
    assert res.exit_code == 1, res.output
    (data,) = json.loads(res.stdout)["runs"]
    assert data["tacho"]["used"] is False
    assert "pulses decrease (counter reset?) at row 2002" in data["tacho"]["note"]
    assert [a["type"] for a in data["alarms"]] == ["overrun"]
    res = invoke(*args[:-2])
    assert "tacho" in res.stdout and "GPS only" in " ".join(res.stdout.split())
    tacho.write_text("t,pulses\nbroken", encoding="utf-8")  # unreadable: a note, not exit 2
    res = invoke(*args)
    assert res.exit_code == 1, res.output
    (data,) = json.loads(res.stdout)["runs"]
    assert data["tacho"]["used"] is False and "km from GPS only" in data["tacho"]["note"]
    assert [a["type"] for a in data["alarms"]] == ["overrun"]


def _fleet(world: dict[str, Path], tmp_path: Path) -> Path:
    """A folder of three runs (copies of the cases) and one whose run.json is broken."""
    import shutil

    root = tmp_path / "fleet"
    for kind in ("correct", "overrun", "wrong_track"):
        shutil.copytree(world[kind], root / "depot" / kind)
    bad = root / "depot" / "zz-broken"
    shutil.copytree(world["correct"], bad)
    (bad / "run.json").write_text("{not json", encoding="utf-8")
    return root


def test_many_runs_go_through_the_replayer_and_a_bad_one_does_not_stop_them(
    world: dict[str, Path], tmp_path: Path
) -> None:
    """A folder is searched for runs; the broken run is listed with its error, the three
    others are checked (both alarms found) and the exit code says a run could not be checked."""
    root = _fleet(world, tmp_path)
    res = invoke(
        "possession", "check", root, "--db", world["db"], "--plan", world["overrun_plan"], "--format", "json", "-j", 1
    )
    assert res.exit_code == 2, res.output
    data = json.loads(res.stdout)
    assert [r["run_id"] for r in data["runs"]] == ["PZ-correct-11", "PZ-overrun-31", "PZ-wrong_track-21"]
    (failed,) = data["failed_runs"]
    assert failed["run"].endswith("zz-broken") and "run.json" in failed["error"]
    assert "failed:" in res.stderr and "zz-broken" in res.stderr
    table = invoke("possession", "check", root, "--db", world["db"], "--plan", world["overrun_plan"])
    assert table.exit_code == 2 and "1 run(s) could not be checked" in " ".join(table.stdout.split())


def test_two_workers_give_the_same_report_as_one(world: dict[str, Path], tmp_path: Path) -> None:
    root = _fleet(world, tmp_path)
    args = ("possession", "check", root, "--db", world["db"], "--plan", world["overrun_plan"], "--format", "json")
    one, two = invoke(*args, "--workers", 1), invoke(*args, "--workers", 2)
    assert one.exit_code == two.exit_code == 2
    assert json.loads(one.stdout) == json.loads(two.stdout)


def test_check_files_reports_progress_per_run(world: dict[str, Path]) -> None:
    from fieldlogs.possession.check import check_files

    seen: list[tuple[int, int]] = []
    rep = check_files(
        [world["overrun"], world["correct"], world["overrun"]],
        world["db"],
        world["overrun_plan"],
        workers=1,
        progress=lambda done, total, _run: seen.append((done, total)),
    )
    assert seen == [(1, 2), (2, 2)]  # the repeated folder is checked once
    assert [c.run for c in rep.checks] == [str(world["overrun"]), str(world["correct"])]  # as given, in order
    assert rep.failed == [] and [a.type for a in rep.checks[0].alarms] == ["overrun"]


def test_a_folder_without_runs_exits_2(world: dict[str, Path], tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    res = invoke("possession", "check", tmp_path / "empty", "--db", world["db"], "--plan", world["correct_plan"])
    assert res.exit_code == 2 and "no run folders" in res.stderr
