"""Parse and check the vehicle geometry (``schemas.vehicle``): a ``VEHICLE.toml`` or the
``vehicle`` block of run.json.

Checks: types and ranges of every declared field, unknown keys (warnings, with the
closest known name), unique antenna ids, unique receivers, unique axle ids, every point
inside the vehicle's extent x ∈ [front_x_m − length_m, front_x_m] (±0.5 m for overhanging
antennas), ``tacho_axle`` naming an axle that gives ``wheel_diameter_m`` and ``teeth``.
``tacho_axle`` is required for a train and wherever the run has a tacho stream; the
stream-dependent checks (gnss_obs receivers, tacho) are in ``check_vehicle_streams``.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dbtools.inputs import not_special
from schemas.enums import Severity, VehicleKind
from schemas.errors import FindingsError, InputError
from schemas.findings import Finding
from schemas.frames import suggest
from schemas.vehicle import VEHICLE_SECTIONS, VEHICLE_TOP, VehicleField

#: Tolerance of the extent check [m] (antennas and readers may overhang a little).
EXTENT_TOLERANCE_M = 0.5


class _Sink:
    def __init__(self, file: str | None) -> None:
        self.file = file
        self.items: list[Finding] = []

    def add(self, message: str, where: str, value: Any = None, *, warning: bool = False, limit: Any = None) -> None:
        sev = Severity.WARNING if warning else Severity.ERROR
        self.items.append(
            Finding("vehicle.field", sev, "vehicle", message, file=self.file, column=where, value=value, limit=limit)
        )


def _typed(f: VehicleField, raw: Any) -> tuple[Any, str | None]:
    """(value, None) or (None, reason)."""
    if f.type == "str":
        return (raw, None) if isinstance(raw, str) and raw.strip() else (None, "is not a non-empty text")
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        return None, f"is not a {'whole number' if f.type == 'int' else 'number'}"
    if f.type == "int" and not float(raw).is_integer():
        return None, "is not a whole number"
    v = int(raw) if f.type == "int" else float(raw)
    if not math.isfinite(v):
        return None, "is not finite"
    if (f.min is not None and v < f.min) or (f.max is not None and v > f.max):
        lo = "−∞" if f.min is None else f"{f.min:g}"
        hi = "+∞" if f.max is None else f"{f.max:g}"
        return None, f"= {v:g} {f.unit} is outside [{lo}, {hi}]".replace("  ", " ")
    return v, None


def _fields(sink: _Sink, fields: Sequence[VehicleField], data: Any, prefix: str) -> dict[str, Any]:
    """Typed values of one table; findings for missing, mistyped, out-of-range and unknown keys."""
    if not isinstance(data, dict):
        sink.add(f"'{prefix}' must be a table of keys", prefix, type(data).__name__)
        return {}
    out: dict[str, Any] = {}
    known = [f.name for f in fields]
    for f in fields:
        where = f"{prefix}.{f.name}" if prefix else f.name
        if f.name not in data:
            if f.required:
                sink.add(f"'{where}' is missing ({f.description})", where)
            continue
        v, why = _typed(f, data[f.name])
        if why is not None:
            sink.add(
                f"'{where}' {why}" if why.startswith("=") else f"'{where}' = {data[f.name]!r} {why}",
                where,
                data[f.name],
                limit=[f.min, f.max] if f.min is not None or f.max is not None else None,
            )
            continue
        out[f.name] = v
    for k in data:
        if k not in known and not (prefix == "" and k in {s for s, _, _ in VEHICLE_SECTIONS}):
            hint = suggest(str(k), known)
            msg = f"unknown key '{prefix + '.' if prefix else ''}{k}' ignored" + (
                f" (did you mean '{hint}'?)" if hint else ""
            )
            sink.add(msg, f"{prefix + '.' if prefix else ''}{k}", k, warning=True)
    return out


def _unique(sink: _Sink, items: list[dict[str, Any]], key: str, section: str) -> None:
    seen: dict[str, int] = {}
    for i, it in enumerate(items):
        v = it.get(key)
        if v is None:
            continue
        if v in seen:
            sink.add(
                f"{section}[{i}].{key} '{v}' repeats {section}[{seen[v]}]: each {key} must be unique",
                f"{section}[{i}].{key}",
                v,
            )
        else:
            seen[v] = i


def _sections(sink: _Sink, data: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, fields, is_list in VEHICLE_SECTIONS:
        if name not in data:
            continue
        raw = data[name]
        if is_list:
            if not isinstance(raw, list):
                sink.add(f"'{name}' must be a list of tables ([[{name}]] in TOML)", name, type(raw).__name__)
                continue
            out[name] = [_fields(sink, fields, item, f"{name}[{i}]") for i, item in enumerate(raw)]
        else:
            out[name] = _fields(sink, fields, raw, name)
    _unique(sink, out.get("antennas", []), "id", "antennas")
    _unique(sink, out.get("antennas", []), "receiver", "antennas")
    _unique(sink, out.get("axles", []), "id", "axles")
    return out


def _points(v: dict[str, Any]) -> list[tuple[str, float]]:
    pts = [(f"antennas[{i}].x_m", a["x_m"]) for i, a in enumerate(v.get("antennas", [])) if "x_m" in a]
    pts += [(f"axles[{i}].x_m", a["x_m"]) for i, a in enumerate(v.get("axles", [])) if "x_m" in a]
    for sec in ("balise_reader", "balise_reader_r", "gps_antenna", "gps_antenna_r", "imu", "imu_r"):
        if "x_m" in v.get(sec, {}):
            pts.append((f"{sec}.x_m", v[sec]["x_m"]))
    return pts


def _extent(sink: _Sink, v: dict[str, Any]) -> None:
    length, front = v.get("length_m"), v.get("front_x_m")
    if length is None or front is None:
        return
    if front > length:
        sink.add(
            f"front_x_m = {front:g} m exceeds length_m = {length:g} m: the reference point lies outside the vehicle",
            "front_x_m",
            front,
            limit=[0.0, length],
        )
        return
    lo, hi = front - length - EXTENT_TOLERANCE_M, front + EXTENT_TOLERANCE_M
    for where, x in _points(v):
        if not lo <= x <= hi:
            sink.add(
                f"'{where}' = {x:g} m lies outside the vehicle (x from {front - length:g} to {front:g} m)",
                where,
                x,
                limit=[lo, hi],
            )


def _tacho(sink: _Sink, v: dict[str, Any], needs_tacho: bool) -> None:
    axle_id = v.get("tacho_axle")
    if axle_id is None:
        if needs_tacho:
            why = "a train" if v.get("vehicle_kind") == VehicleKind.TRAIN else "a run with a tacho stream"
            sink.add(f"'tacho_axle' is missing: {why} needs the axle of its tachometer", "tacho_axle")
        return
    axles = {a.get("id"): (i, a) for i, a in enumerate(v.get("axles", []))}
    if axle_id not in axles:
        hint = suggest(str(axle_id), [str(k) for k in axles if k])
        sink.add(
            f"tacho_axle '{axle_id}' is not an axle id" + (f" (did you mean '{hint}'?)" if hint else ""),
            "tacho_axle",
            axle_id,
            limit=sorted(str(k) for k in axles if k),
        )
        return
    i, axle = axles[axle_id]
    for key in ("wheel_diameter_m", "teeth"):
        if key not in axle:
            sink.add(f"axles[{i}].{key} is missing: the tacho axle '{axle_id}' needs it", f"axles[{i}].{key}")


def check_vehicle(
    data: Any, *, file: str | None = None, has_tacho: bool = False
) -> tuple[dict[str, Any] | None, list[Finding]]:
    """The checked vehicle block (typed values, unknown keys dropped) and findings.

    None when any error was found (the findings say where).
    """
    sink = _Sink(file)
    if not isinstance(data, dict):
        sink.add("the vehicle block must be a table (JSON object)", "vehicle", type(data).__name__)
        return None, sink.items
    v = _fields(sink, VEHICLE_TOP, data, "")
    kind = v.get("vehicle_kind")
    if kind is not None and kind not in {k.value for k in VehicleKind}:
        sink.add(
            f"vehicle_kind '{kind}' is not train or road_rail",
            "vehicle_kind",
            kind,
            limit=[k.value for k in VehicleKind],
        )
    v.update(_sections(sink, data))
    _extent(sink, v)
    _tacho(sink, v, needs_tacho=has_tacho or kind == VehicleKind.TRAIN)
    if any(f.severity == Severity.ERROR for f in sink.items):
        return None, sink.items
    return v, sink.items


def tacho_wheel(vehicle: dict[str, Any]) -> tuple[float, int] | None:
    """(wheel_diameter_m, teeth) of the tacho axle of a checked vehicle block, or None."""
    axle_id = vehicle.get("tacho_axle")
    for a in vehicle.get("axles", []):
        if a.get("id") == axle_id and "wheel_diameter_m" in a and "teeth" in a:
            return float(a["wheel_diameter_m"]), int(a["teeth"])
    return None


def receivers(vehicle: dict[str, Any]) -> list[str]:
    return [str(a["receiver"]) for a in vehicle.get("antennas", []) if "receiver" in a]


def load_vehicle(path: Path, *, has_tacho: bool = False) -> tuple[dict[str, Any], list[Finding]]:
    """A VEHICLE.toml, checked: (block, warnings). InputError when it is not TOML,
    FindingsError (exit 1) when it has errors."""
    path = not_special(Path(path), "vehicle file (TOML)")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InputError("vehicle file not found", path=path) from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from exc
    vehicle, findings = check_vehicle(data, file=str(path), has_tacho=has_tacho)
    if vehicle is None:
        errors = [f for f in findings if f.severity == Severity.ERROR]
        raise FindingsError(
            f"{len(errors)} error(s) in the vehicle file, first: {errors[0].column}: {errors[0].message}; "
            "nothing was written",
            errors,
            path=path,
        )
    return vehicle, findings
