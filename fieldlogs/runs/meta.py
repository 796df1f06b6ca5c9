"""``run.json`` of a run folder (SPEC §4): its typed fields (:data:`schemas.logs.RUN_JSON`),
the optional blocks (vehicle, GNSS receiver, sources, radar) and every problem as a finding
naming the file and the field. Read by :class:`fieldlogs.runs.handle.Run`; the blocks are checked by
:mod:`fieldlogs.runs.blocks` and :mod:`fieldlogs.runs.vehicle`."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from schemas.enums import Severity, VehicleKind
from schemas.findings import Finding
from schemas.logs import RUN_JSON, RunField

#: run.json blocks written only when present.
OPTIONAL_BLOCKS = ("vehicle", "gnss", "sources")


@dataclass
class RunMeta:
    """``run.json``."""

    run_id: str
    vehicle_id: str
    vehicle_kind: str
    wheel_diameter_m: float | None
    """Needed for a train and wherever the run has a tacho stream (``Run`` says so); None otherwise."""
    teeth: int | None
    start_time: str
    db_version: str | None = None
    notes: str = ""
    vehicle: dict[str, Any] | None = None
    """Vehicle geometry (``schemas.vehicle``), checked by ``runs.vehicle``."""
    gnss: dict[str, Any] | None = None
    """Navigation-header parameters (``schemas.gnss.GNSS_BLOCK``)."""
    sources: list[Any] | None = None
    """Provenance of an imported run (``logs import``)."""
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        extra = d.pop("extra")
        for block in OPTIONAL_BLOCKS:
            if d[block] is None:
                del d[block]
        return {**d, **extra}


def load_run_json(path: Path) -> tuple[Any, list[Finding]]:
    try:
        return json.loads(Path(path).read_text(encoding="utf-8")), []
    except FileNotFoundError:
        return None, [
            Finding("log.missing_run_json", Severity.ERROR, "run.json", "run.json is missing", file=str(path))
        ]
    except IsADirectoryError:
        return None, [Finding("log.bad_run_json", Severity.ERROR, "run.json", "run.json is a folder", file=str(path))]
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        return None, [
            Finding(
                "log.bad_run_json",
                Severity.ERROR,
                "run.json",
                f"not valid JSON: {exc}",
                file=str(path),
                row=getattr(exc, "lineno", None),
            )
        ]


def field_finding(path: Path, name: str, message: str, value: object = None, limit: object = None) -> Finding:
    return Finding(
        "log.run_json_field", Severity.ERROR, "run.json", message, file=str(path), column=name, value=value, limit=limit
    )


def typed_value(f: RunField, raw: Any, path: Path) -> tuple[Any, Finding | None]:
    """One present field of ``run.json`` as its declared type, or the finding why not."""
    if f.type in (dict, list):
        if isinstance(raw, f.type):
            return raw, None
        kind = "object" if f.type is dict else "list"
        return None, field_finding(path, f.name, f"field '{f.name}' must be a JSON {kind}", type(raw).__name__)
    try:
        if f.type is int and (isinstance(raw, bool) or (isinstance(raw, float) and not raw.is_integer())):
            raise ValueError(raw)
        v = f.type(raw)
        if f.type is float and not np.isfinite(v):
            raise ValueError(raw)
    except (TypeError, ValueError, OverflowError):
        return None, field_finding(path, f.name, f"field '{f.name}' = {raw!r} is not a {f.type.__name__}", str(raw))
    return v, None


def typed_fields(data: dict[str, Any], path: Path) -> tuple[dict[str, Any], list[Finding]]:
    """Every field of ``run.json`` that parses, plus findings for the others."""
    findings: list[Finding] = []
    values: dict[str, Any] = {}
    for f in RUN_JSON:
        if f.name not in data or data[f.name] in (None, ""):
            if f.required:
                findings.append(field_finding(path, f.name, f"field '{f.name}' is missing"))
            continue
        v, problem = typed_value(f, data[f.name], path)
        if problem is not None:
            findings.append(problem)
        else:
            values[f.name] = v
    kinds = [k.value for k in VehicleKind]
    kind = values.get("vehicle_kind")
    if kind is not None and kind not in kinds:
        findings.append(
            field_finding(path, "vehicle_kind", f"vehicle_kind '{kind}' is not train or road_rail", kind, kinds)
        )
        del values["vehicle_kind"]
    if values.get("vehicle_kind") == VehicleKind.TRAIN.value:
        findings += wheel_needed(values, path, "a train's pulses are its odometry")
    for name in ("wheel_diameter_m", "teeth"):
        v = values.get(name)
        if v is not None and not v > 0:
            findings.append(field_finding(path, name, f"{name} must be > 0", v, 0))
            del values[name]
    return values, findings


def wheel_needed(values: dict[str, Any], path: Path, why: str) -> list[Finding]:
    """A finding for each wheel field (wheel_diameter_m, teeth) that ``values`` lacks."""
    return [
        field_finding(path, name, f"field '{name}' is missing ({why})")
        for name in ("wheel_diameter_m", "teeth")
        if values.get(name) is None
    ]


def parse_run_json(path: Path) -> tuple[RunMeta | None, list[Finding]]:
    """Read and check ``run.json``; findings for missing or mistyped fields."""
    data, findings = load_run_json(path)
    if findings:
        return None, findings
    if not isinstance(data, dict):
        return None, [Finding("log.bad_run_json", Severity.ERROR, "run.json", "must be a JSON object", file=str(path))]
    values, findings = typed_fields(data, path)
    if any(f.severity == Severity.ERROR for f in findings):
        return None, findings
    known = {f.name for f in RUN_JSON}
    values.setdefault("wheel_diameter_m", None)
    values.setdefault("teeth", None)
    meta = RunMeta(**values, extra={k: v for k, v in data.items() if k not in known})
    return meta, findings


def block_findings(data: dict[str, Any], path: Path, *, has_tacho: bool) -> list[Finding]:
    """Findings of run.json's vehicle and gnss blocks (``runs.vehicle``, ``runs.blocks``)."""
    from fieldlogs.runs.blocks import check_gnss_block, check_vehicle_block

    out: list[Finding] = []
    if isinstance(data.get("vehicle"), dict):
        out += check_vehicle_block(data, str(path), has_tacho=has_tacho)
    if isinstance(data.get("gnss"), dict):
        out += check_gnss_block(data["gnss"], str(path))
    return out
