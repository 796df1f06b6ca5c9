"""Settings as data: every tunable number declared once with its default, unit, allowed
range and one-line meaning.

A configuration section is a frozen dataclass whose fields are made with :func:`setting`;
its ``__post_init__`` calls :func:`check_ranges`, so a value outside its range (a negative
threshold, a zero window) can never exist, whether it comes from a file, the command line or
code. :func:`section_from_dict` reads a TOML table into a section (unknown keys and wrong
types are errors naming the key), :func:`render_toml` writes a section tree back as
commented TOML — every setting with its meaning, unit and range — which read back gives the
same tree, and :func:`describe` gives the same as data (``config show --format json``).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field, fields, is_dataclass, replace
from typing import Any, TypeVar

from schemas.errors import InputError

T = TypeVar("T")
#: Key of a field's :class:`Setting` in its dataclass metadata.
META = "setting"


@dataclass(frozen=True)
class Setting:
    """What a configuration field means and which values it may take."""

    meaning: str
    unit: str = ""
    ge: float | None = None
    """Smallest allowed value (inclusive)."""
    gt: float | None = None
    """Values must be greater than this."""
    le: float | None = None
    """Largest allowed value (inclusive)."""
    lt: float | None = None
    """Values must be less than this."""

    def range_text(self) -> str:
        lo = f"≥ {self.ge:g}" if self.ge is not None else (f"> {self.gt:g}" if self.gt is not None else "")
        hi = f"≤ {self.le:g}" if self.le is not None else (f"< {self.lt:g}" if self.lt is not None else "")
        return ", ".join(p for p in (lo, hi) if p)

    def violates(self, v: float) -> bool:
        return (
            (self.ge is not None and not v >= self.ge)
            or (self.gt is not None and not v > self.gt)
            or (self.le is not None and not v <= self.le)
            or (self.lt is not None and not v < self.lt)
        )


def setting(
    default: Any,
    meaning: str,
    unit: str = "",
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
) -> Any:
    """A dataclass field carrying its :class:`Setting` (use in frozen config sections)."""
    return field(default=default, metadata={META: Setting(meaning, unit, ge, gt, le, lt)})


class SettingError(InputError):
    """A setting with a value it may not take."""


def setting_of(f: dataclasses.Field[Any]) -> Setting | None:
    s = f.metadata.get(META)
    return s if isinstance(s, Setting) else None


def _numbers(v: Any) -> Iterator[float]:
    if isinstance(v, bool):
        return
    if isinstance(v, int | float):
        yield float(v)
    elif isinstance(v, tuple | list):
        for x in v:
            yield from _numbers(x)


def check_ranges(section: Any, name: str = "") -> None:
    """Raise :class:`SettingError` for the first field of ``section`` outside its range
    (every element of a tuple field is checked; non-finite numbers are never allowed)."""
    for f in fields(section):
        s = setting_of(f)
        if s is None:
            continue
        v = getattr(section, f.name)
        key = f"{name}.{f.name}" if name else f.name
        for x in _numbers(v):
            if not math.isfinite(x) or s.violates(x):
                allowed = s.range_text() or "a finite number"
                unit = f" {s.unit}" if s.unit else ""
                raise SettingError(f"'{key}' = {v!r}{unit} is out of range (allowed: {allowed})")


def section_from_dict(current: T, values: dict[str, Any], section: str, source: str) -> T:
    """``current`` (a frozen section) with ``values`` from the TOML table ``[section]``:
    unknown keys, wrong types and values out of range are errors naming the key."""
    known = [f.name for f in fields(current)]  # type: ignore[arg-type]
    updates = {}
    for k, v in values.items():
        if k not in known:
            raise InputError(f"unknown key '{section}.{k}' (known: {', '.join(known)})", path=source)
        updates[k] = typed(source, f"{section}.{k}", getattr(current, k), v)
    try:
        return replace(current, **updates)  # type: ignore[type-var]
    except SettingError as exc:
        raise SettingError(_qualified(exc.message, section), path=source) from None


def _qualified(message: str, section: str) -> str:
    return message if message.startswith(f"'{section}.") else message.replace("'", f"'{section}.", 1)


def typed(source: str, key: str, default: Any, value: Any) -> Any:
    """``value`` converted to the type of ``default`` (bool, int, float, tuple), or an error."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise InputError(f"'{key}' must be true or false, not {value!r}", path=source)
        return value
    if isinstance(default, tuple):
        if not isinstance(value, list):
            raise InputError(f"'{key}' must be a list, not {value!r}", path=source)
        return tuple(typed(source, key, default[0] if default else value[0], v) for v in value)
    if isinstance(default, int):
        if not isinstance(value, int) or isinstance(value, bool):
            raise InputError(f"'{key}' must be a whole number, not {value!r}", path=source)
        return value
    if isinstance(default, float):
        if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
            raise InputError(f"'{key}' must be a number, not {value!r}", path=source)
        return float(value)
    return value


# ------------------------------------------------------------------------------ rendering
def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, int):
        return str(v)
    if isinstance(v, tuple | list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _comment(s: Setting) -> str:
    extra = ", ".join(p for p in ((f"[{s.unit}]" if s.unit else ""), s.range_text()) if p)
    return f"# {s.meaning}" + (f" ({extra})" if extra else "")


def _doc_lines(obj: Any) -> list[str]:
    doc = (type(obj).__doc__ or "").strip().splitlines()
    if not doc:
        return []
    first = _ROLE.sub(r"\1", doc[0].strip())  # :mod:`x` → x
    return [f"# {first}"]


_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def render_toml(tree: Any, only: str | None = None) -> str:
    """Commented TOML of a tree of sections (a dataclass whose fields are sections or plain
    settings); ``only`` keeps one section. Reading it back gives the same tree."""
    out: list[str] = []
    plain = [f for f in fields(tree) if not is_dataclass(getattr(tree, f.name))]
    if only is None and plain:
        for f in plain:
            s = setting_of(f)
            if s is not None:
                out.append(_comment(s))
            out.append(f"{f.name} = {_toml_value(getattr(tree, f.name))}")
        out.append("")
    for f in fields(tree):
        sec = getattr(tree, f.name)
        if not is_dataclass(sec) or (only is not None and f.name != only):
            continue
        out += _doc_lines(sec)
        out.append(f"[{f.name}]")
        for g in fields(sec):
            s = setting_of(g)
            if s is not None:
                out.append(_comment(s))
            out.append(f"{g.name} = {_toml_value(getattr(sec, g.name))}")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


def describe(tree: Any, only: str | None = None) -> dict[str, Any]:
    """Every setting as data: ``{section: {key: {value, unit, meaning, range}}}`` (plain
    settings of the root under their own names)."""
    out: dict[str, Any] = {}

    def entry(f: dataclasses.Field[Any], v: Any) -> dict[str, Any]:
        s = setting_of(f) or Setting("")
        return {
            "value": list(v) if isinstance(v, tuple) else v,
            "unit": s.unit,
            "meaning": s.meaning,
            "range": s.range_text(),
        }

    for f in fields(tree):
        v = getattr(tree, f.name)
        if is_dataclass(v):
            if only is None or f.name == only:
                out[f.name] = {g.name: entry(g, getattr(v, g.name)) for g in fields(v)}
        elif only is None:
            out[f.name] = entry(f, v)
    return out


def undocumented(tree: Any) -> list[str]:
    """Settings of a tree without a :class:`Setting` or without a meaning (a test keeps this empty)."""
    missing = []
    for f in fields(tree):
        v = getattr(tree, f.name)
        for g in fields(v) if is_dataclass(v) else [f]:
            s = setting_of(g)
            if s is None or not s.meaning.strip():
                missing.append(f"{f.name}.{g.name}" if is_dataclass(v) else f.name)
    return missing
