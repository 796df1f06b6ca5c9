"""``logs repair``: safe repairs into a new folder; the input is never touched."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.tabular import sha256_file
from fieldlogs.quality.checks import check_run
from fieldlogs.quality.repair import REPAIR_LOG, repair_run, repair_stream
from fieldlogs.runs.handle import Run
from fieldlogs.runs.write import write_run
from schemas.errors import FindingsError, RefusedError
from tests.fieldlogs.make_runs import make_meta, make_run, synthetic_streams


def hashes(folder: Path) -> dict[str, str]:
    return {p.name: sha256_file(p) for p in sorted(folder.iterdir())}


def damaged_streams() -> tuple[dict[str, pd.DataFrame], dict[str, pd.DataFrame]]:
    """(clean, damaged): tacho with swapped rows, an exact duplicate, a same-t row and a reset."""
    clean = synthetic_streams(10)
    streams = {k: v.copy() for k, v in clean.items()}
    tacho = streams["tacho"]
    p = tacho["pulses"].to_numpy().copy()
    p[60:] -= p[59]  # counter reset after row 59 (line 64 once two rows are added before it)
    tacho["pulses"] = p
    other = tacho.iloc[[30]].assign(pulses=tacho["pulses"].iloc[30] + 1)
    rows = [*range(0, 20), 21, 20, *range(22, 31)]  # lines 22/23 swapped
    tacho = pd.concat([tacho.iloc[rows], tacho.iloc[[25]], other, tacho.iloc[31:]], ignore_index=True)
    streams["tacho"] = tacho
    imu = streams["imu"]
    streams["imu"] = pd.concat([imu.iloc[:500], imu.iloc[[499]], imu.iloc[500:]], ignore_index=True)
    return clean, streams


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_repair_fixes_order_duplicates_and_resets(tmp_path: Path, fmt: str) -> None:
    clean, streams = damaged_streams()
    src = write_run(tmp_path / "run", make_meta(), streams, fmt=fmt)  # type: ignore[arg-type]
    before = hashes(src)
    rules = {f.rule for f in check_run(src)}
    assert {"log.unsorted", "log.duplicate_row", "log.duplicate_t", "log.pulse_reset"} <= rules

    res = repair_run(src, tmp_path / "fixed")
    assert hashes(src) == before  # input untouched
    assert res.remaining == [] and res.format == fmt
    out = Run(tmp_path / "fixed")
    tacho = out.stream("tacho")
    assert tacho is not None
    pd.testing.assert_frame_equal(tacho, out.stream("tacho"))
    assert tacho["pulses"].tolist() == clean["tacho"]["pulses"].tolist()  # exactly the original count
    np.testing.assert_allclose(tacho["t"], clean["tacho"]["t"])
    imu = out.stream("imu")
    assert imu is not None and len(imu) == len(clean["imu"])

    log = json.loads((tmp_path / "fixed" / REPAIR_LOG).read_text(encoding="utf-8"))
    assert log["source"] == str(src) and log["remaining"] == {"errors": 0, "warnings": 0, "by_rule": {}}
    t_log = {a["action"]: a for a in log["streams"][0]["actions"]}
    assert log["streams"][0]["stream"] == "tacho"
    assert (log["streams"][0]["rows_in"], log["streams"][0]["rows_out"]) == (102, 100)
    assert t_log["sort_by_t"]["count"] == 2  # line 23 (t of row 20 after 21) and the repeated row 25
    assert t_log["drop_duplicate_rows"]["rows"] == [[33, 33]]
    assert t_log["drop_duplicate_t"]["rows"] == [[34, 34]]
    assert "keeping the first" in t_log["drop_duplicate_t"]["message"]
    assert t_log["bridge_pulse_reset"]["count"] == 1 and t_log["bridge_pulse_reset"]["rows"] == [[64, 64]]
    i_log = log["streams"][1]["actions"]
    assert [(a["action"], a["count"], a["rows"]) for a in i_log] == [("drop_duplicate_rows", 1, [[502, 502]])]
    assert [s["actions"] for s in log["streams"][2:]] == [[], [], []]


def test_clean_run_is_copied_unchanged(tmp_path: Path) -> None:
    src = make_run(tmp_path / "run", 3)
    res = repair_run(src, tmp_path / "out")
    assert not res.changed
    for name in Run(src).streams_present():
        pd.testing.assert_frame_equal(Run(src).stream(name), Run(tmp_path / "out").stream(name))


def test_repair_refuses_unsafe_outputs(tmp_path: Path) -> None:
    src = make_run(tmp_path / "run", 2)
    before = hashes(src)
    (tmp_path / "exists").mkdir()
    with pytest.raises(RefusedError, match="exists"):
        repair_run(src, tmp_path / "exists")
    with pytest.raises(RefusedError):
        repair_run(src, src, force=True)
    with pytest.raises(RefusedError):
        repair_run(src, src / "fixed", force=True)
    with pytest.raises(RefusedError):
        repair_run(src, tmp_path, force=True)  # would replace the folder holding the input
    assert hashes(src) == before
    repair_run(src, tmp_path / "exists", force=True)
    assert (tmp_path / "exists" / REPAIR_LOG).exists()


def test_repair_refuses_what_a_person_must_fix(tmp_path: Path) -> None:
    src = make_run(tmp_path / "run", 2)
    lines = (src / "tacho.csv").read_text(encoding="utf-8").splitlines()
    lines[4] = "0.3,lots"
    (src / "tacho.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(FindingsError) as exc:
        repair_run(src, tmp_path / "out")
    assert [(f.rule, f.row, f.column) for f in exc.value.findings] == [("schema.type", 5, "pulses")]
    assert not (tmp_path / "out").exists()


def test_small_drops_are_not_repaired() -> None:
    frame = pd.DataFrame({"t": [0.0, 0.1, 0.2, 0.3], "pulses": pd.array([100, 110, 105, 120], dtype="Int64")})
    fixed, rep = repair_stream("tacho", frame, "tacho.csv")
    assert fixed["pulses"].tolist() == [100, 110, 105, 120] and rep.actions == []


def test_reset_with_missing_pulses() -> None:
    frame = pd.DataFrame({"t": [0.0, 0.1, 0.2, 0.3, 0.4], "pulses": pd.array([100, 110, None, 5, 12], dtype="Int64")})
    fixed, rep = repair_stream("tacho", frame, "tacho.csv")
    assert fixed["pulses"].tolist() == [100, 110, pd.NA, 115, 122]
    assert rep.actions[0].rows == [[5, 5]]
    assert frame["pulses"].tolist() == [100, 110, pd.NA, 5, 12]  # input frame untouched


def _with_a_small_pulse_drop(src: Path) -> int:
    """A tacho glitch (the counter dips by 5 and recovers) besides a repairable swap: the
    swap is safe to repair, the glitch is not. Returns the glitch's line in the repaired run."""
    lines = (src / "tacho.csv").read_text(encoding="utf-8").splitlines()
    t, p = lines[40].split(",")
    lines[40] = f"{t},{int(p) - 5 - (int(p) - int(lines[39].split(',')[1]))}"
    lines[5], lines[6] = lines[6], lines[5]
    (src / "tacho.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return 41


def test_problems_left_after_the_repair_refuse_it_naming_them(tmp_path: Path) -> None:
    src = make_run(tmp_path / "run", 10)
    line = _with_a_small_pulse_drop(src)
    assert {"log.unsorted", "log.pulse_decrease"} <= {f.rule for f in check_run(src)}
    before = hashes(src)
    with pytest.raises(FindingsError) as exc:
        repair_run(src, tmp_path / "out")
    assert "remain after the safe repairs" in exc.value.message and "nothing was written" in exc.value.message
    left = [(f.rule, f.file, f.row) for f in exc.value.findings]
    assert left == [("log.pulse_decrease", str(tmp_path / "out" / "tacho.csv"), line)]  # in the repaired run
    assert not (tmp_path / "out").exists() and hashes(src) == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]  # no temporary left behind


def test_warnings_left_are_logged_or_refused_with_strict(tmp_path: Path) -> None:
    src = make_run(tmp_path / "run", 3)
    lines = (src / "imu.csv").read_text(encoding="utf-8").splitlines()
    del lines[20:120]  # a 1 s gap: a warning of logs check, nothing a repair may fill
    (src / "imu.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    warned = check_run(src)
    assert warned and all(f.severity == "warning" for f in warned)
    res = repair_run(src, tmp_path / "out")
    assert [f.rule for f in res.remaining] == [f.rule for f in warned]
    log = json.loads((tmp_path / "out" / REPAIR_LOG).read_text(encoding="utf-8"))
    assert log["remaining"]["errors"] == 0 and log["remaining"]["warnings"] == len(warned)
    with pytest.raises(FindingsError):
        repair_run(src, tmp_path / "strict", strict=True)
    assert not (tmp_path / "strict").exists()
