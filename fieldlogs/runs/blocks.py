"""Checks of run.json's ``vehicle`` and ``gnss`` blocks (findings, never exceptions).

``vehicle``: everything ``runs.vehicle.check_vehicle`` checks, plus agreement with the
top-level fields: vehicle_id and vehicle_kind equal, wheel_diameter_m and teeth equal to
the tacho axle's. ``gnss``: known keys (``schemas.gnss.GNSS_BLOCK``), coefficient lists of
the right length with finite numbers, an integer leap-second count in [0, 100], time
corrections as objects with numeric a0_s, a1_s_per_s, t_ref_s and week.
"""

from __future__ import annotations

import math
from typing import Any

from fieldlogs.runs.vehicle import check_vehicle, tacho_wheel
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.frames import suggest
from schemas.gnss import GNSS_BLOCK, GNSS_BLOCK_LENGTHS

CORRECTION_KEYS = ("a0_s", "a1_s_per_s", "t_ref_s", "week")


def _err(rule: str, table: str, msg: str, file: str, column: str, value: Any = None) -> Finding:
    return Finding(rule, Severity.ERROR, table, msg, file=file, column=column, value=value)


def check_vehicle_block(data: dict[str, Any], file: str, *, has_tacho: bool) -> list[Finding]:
    vehicle, findings = check_vehicle(data["vehicle"], file=file, has_tacho=has_tacho)
    for f in findings:
        f.column = f"vehicle.{f.column}" if f.column else "vehicle"
    if vehicle is None:
        return findings
    for key in ("vehicle_id", "vehicle_kind"):
        if key in data and data[key] != vehicle.get(key):
            findings.append(
                _err(
                    "vehicle.mismatch",
                    "vehicle",
                    f"vehicle.{key} '{vehicle.get(key)}' differs from run.json {key} '{data[key]}'",
                    file,
                    f"vehicle.{key}",
                    vehicle.get(key),
                )
            )
    wheel = tacho_wheel(vehicle)
    if wheel is not None:
        for key, v in zip(("wheel_diameter_m", "teeth"), wheel, strict=True):
            top = data.get(key)
            if isinstance(top, (int, float)) and not isinstance(top, bool) and not math.isclose(float(top), v):
                findings.append(
                    _err(
                        "vehicle.mismatch",
                        "vehicle",
                        f"run.json {key} = {top} differs from the tacho axle's {v:g}",
                        file,
                        key,
                        top,
                    )
                )
    return findings


def _numbers(v: Any, n: int | None) -> bool:
    return (
        isinstance(v, list)
        and (n is None or len(v) == n)
        and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
    )


def check_gnss_block(block: dict[str, Any], file: str) -> list[Finding]:
    out: list[Finding] = []
    known = [k for k, _ in GNSS_BLOCK]
    for k, v in block.items():
        col = f"gnss.{k}"
        if k not in known:
            hint = suggest(k, known)
            out.append(
                Finding(
                    "gnss.block",
                    Severity.WARNING,
                    "gnss",
                    f"unknown key '{col}' ignored" + (f" (did you mean '{hint}'?)" if hint else ""),
                    file=file,
                    column=col,
                    value=k,
                )
            )
        elif k in GNSS_BLOCK_LENGTHS and not _numbers(v, GNSS_BLOCK_LENGTHS[k]):
            out.append(
                _err("gnss.block", "gnss", f"'{col}' must be {GNSS_BLOCK_LENGTHS[k]} finite numbers", file, col, str(v))
            )
        elif k == "leap_seconds" and not (isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 100):
            out.append(
                _err(
                    "gnss.block",
                    "gnss",
                    f"'{col}' = {v!r} is not a whole number of seconds in [0, 100]",
                    file,
                    col,
                    str(v),
                )
            )
        elif k == "time_corrections":
            out += _corrections(v, file)
    return out


def _corrections(v: Any, file: str) -> list[Finding]:
    if not isinstance(v, list):
        return [_err("gnss.block", "gnss", "'gnss.time_corrections' must be a list", file, "gnss.time_corrections")]
    out = []
    for i, c in enumerate(v):
        col = f"gnss.time_corrections[{i}]"
        ok = (
            isinstance(c, dict)
            and isinstance(c.get("type"), str)
            and _numbers([c.get(k) for k in CORRECTION_KEYS], None)
        )
        if not ok:
            out.append(
                _err(
                    "gnss.block",
                    "gnss",
                    f"'{col}' needs type and numeric {', '.join(CORRECTION_KEYS)}",
                    file,
                    col,
                    str(c),
                )
            )
    return out
