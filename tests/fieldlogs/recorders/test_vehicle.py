"""Vehicle geometry: the hand-made VEHICLE.toml, and every check with its finding."""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path
from typing import Any

import pytest

from fieldlogs.runs.handle import Run
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.vehicle import check_vehicle, load_vehicle, tacho_wheel
from fieldlogs.runs.write import write_run
from schemas.errors import FindingsError


@pytest.fixture
def vehicle(data: Path) -> dict[str, Any]:
    return tomllib.loads((data / "vehicle.toml").read_text())


def test_hand_made_vehicle_file(data: Path) -> None:
    v, warnings = load_vehicle(data / "vehicle.toml")
    assert warnings == []
    assert [a["receiver"] for a in v["antennas"]] == ["RX211", "sample", "gnss"]
    assert tacho_wheel(v) == (0.86, 90)
    assert v["imu"]["pitch_deg"] == 0.2


def _messages(data: Any, **kw: Any) -> list[tuple[str, str]]:
    _, findings = check_vehicle(data, **kw)
    return [(f.column or "", f.message) for f in findings]


@pytest.mark.parametrize(
    ("edit", "column", "text"),
    [
        (lambda v: v["antennas"].append(dict(v["antennas"][0])), "antennas[3].id", "repeats antennas[0]"),
        (lambda v: v["antennas"][1].update(receiver="RX211"), "antennas[1].receiver", "must be unique"),
        (lambda v: v["axles"][1].update(id="A1"), "axles[1].id", "must be unique"),
        (lambda v: v["antennas"][0].update(x_m=12.0), "antennas[0].x_m", "outside the vehicle"),
        (lambda v: v["antennas"][0].update(z_m=12.0), "antennas[0].z_m", "outside [-1, 8]"),
        (lambda v: v["antennas"][0].update(y_m="left"), "antennas[0].y_m", "is not a number"),
        (lambda v: v.pop("length_m"), "length_m", "is missing"),
        (lambda v: v.update(vehicle_kind="tram"), "vehicle_kind", "not train or road_rail"),
        (lambda v: v.update(front_x_m=25.0), "front_x_m", "exceeds length_m"),
        (lambda v: v.pop("tacho_axle"), "tacho_axle", "a train needs the axle"),
        (lambda v: v.update(tacho_axle="A9"), "tacho_axle", "is not an axle id"),
        (lambda v: v["axles"][0].pop("teeth"), "axles[0].teeth", "tacho axle 'A1' needs it"),
        (lambda v: v["axles"][0].update(teeth=90.5), "axles[0].teeth", "not a whole number"),
        (lambda v: v.update(antennas={"id": "x"}), "antennas", "must be a list of tables"),
        (lambda v: v.update(gps_antenna_r={"x_m": -12.0, "y_m": 0.0}), "gps_antenna_r.x_m", "outside the vehicle"),
        (lambda v: v.update(imu_r={"x_m": -9.0, "y_m": 0.0}), "imu_r.z_m", "is missing"),
    ],
)
def test_each_check(vehicle: dict[str, Any], edit: Any, column: str, text: str) -> None:
    v = copy.deepcopy(vehicle)
    edit(v)
    found = _messages(v)
    assert any(c == column and text in m for c, m in found), found
    assert check_vehicle(v)[0] is None


def test_unknown_key_is_a_warning_with_a_hint(vehicle: dict[str, Any]) -> None:
    v = copy.deepcopy(vehicle)
    v["antennas"][0]["hieght_m"] = 1.0
    out, findings = check_vehicle(v)
    assert out is not None
    assert [(f.severity, f.column) for f in findings] == [("warning", "antennas[0].hieght_m")]


def test_tacho_axle_only_where_it_applies(vehicle: dict[str, Any]) -> None:
    v = copy.deepcopy(vehicle)
    v.update(vehicle_kind="road_rail")
    v.pop("tacho_axle")
    assert check_vehicle(v)[0] is not None  # a road-rail vehicle without a tacho stream
    assert any("a run with a tacho stream" in m for _, m in _messages(v, has_tacho=True))


def test_load_vehicle_refuses_with_the_first_error(tmp_path: Path, data: Path) -> None:
    p = tmp_path / "v.toml"
    p.write_text((data / "vehicle.toml").read_text().replace("z_m = 3.9", "z_m = 39.0", 1))
    with pytest.raises(FindingsError, match=r"antennas\[0\].z_m"):
        load_vehicle(p)


def test_run_json_block_checked_against_the_run(tmp_path: Path, vehicle: dict[str, Any]) -> None:
    meta = RunMeta("R1", "V01", "train", 0.86, 90, "2026-12-01T10:00:00+00:00", vehicle=vehicle)
    write_run(tmp_path / "r", meta, {})
    assert [f for f in Run(tmp_path / "r").findings if f.severity == "error"] == []
    bad = copy.deepcopy(vehicle)
    bad["antennas"][0]["x_m"] = 50.0
    raw = json.loads((tmp_path / "r" / "run.json").read_text())
    raw.update(vehicle=bad, teeth=100, gnss={"klobuchar_alpha": [1.0, 2.0], "leap_seconds": 18.5, "foo": 1})
    (tmp_path / "r" / "run.json").write_text(json.dumps(raw))
    cols = {(f.rule, f.column) for f in Run(tmp_path / "r").findings}
    assert ("vehicle.field", "vehicle.antennas[0].x_m") in cols
    assert ("gnss.block", "gnss.klobuchar_alpha") in cols
    assert ("gnss.block", "gnss.leap_seconds") in cols
    assert ("gnss.block", "gnss.foo") in cols
    bad["antennas"][0]["x_m"] = 5.0
    raw.update(vehicle=bad)
    (tmp_path / "r" / "run.json").write_text(json.dumps(raw))
    assert ("vehicle.mismatch", "teeth") in {(f.rule, f.column) for f in Run(tmp_path / "r").findings}
