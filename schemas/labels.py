"""Human labels of machine column names, the one rendering standard's vocabulary (issue 33).

A machine name (``km_m``, ``mean_correction_pct``, ``gps_trusted_share``) is what CSV, JSON
and Parquet files meant for programs carry; a person reads its label, the same in the
terminal and on an HTML page: the quantity in words, then its unit in brackets
(``km [m]``, ``mean correction [%]``; a share, whose values carry their ``%``: ``GPS trusted share``).

The unit is the one the column's declaration in :mod:`schemas` gives (``Column.unit``, looked
up by name over :data:`schemas.catalog.ALL_SCHEMAS`; no name is declared with two units, a test
checks it); an undeclared name (a report's derived figure) takes it from the suite's naming
rule, the unit suffix of the name (``_m``, ``_s``, ``_pct`` …, :data:`SUFFIX_UNITS`).

A share (a name ending in ``_share`` or starting with ``share_``) is a fraction 0–1 in the
machine files and a percentage for people: :func:`display` says to multiply it by 100
(:data:`PERCENT`), so no person reads 0.993 for 99.3 %.

Words: the unit suffix is dropped, a count's ``n_`` prefix too (``n_slips`` → ``slips``),
underscores become spaces (a name qualifying a declared one, ``lat_new`` or ``t_pass``, takes its
unit), abbreviations are spelt as people write them (:data:`WORDS`:
``gps`` → ``GPS``), and a few identifiers read better by their short name (:data:`NAMES`:
``line_code`` → ``line``). A text that is not a machine name (it has a space, a bracket, a
capital …) is a label already and is returned as given.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

#: Unit suffix of a machine name → its unit (the suite's naming rule, longest suffix first).
SUFFIX_UNITS: dict[str, str] = {
    "_mps2": "m/s²",
    "_dbhz": "dB-Hz",
    "_radps": "rad/s",
    "_mps": "m/s",
    "_kmh": "km/h",
    "_pct": "%",
    "_deg": "deg",
    "_rad": "rad",
    "_mm": "mm",
    "_km": "km",
    "_hz": "Hz",
    "_db": "dB",
    "_ms": "ms",
    "_m": "m",
    "_s": "s",
}

#: Identifiers people call by a shorter name.
NAMES: dict[str, str] = {
    "line_code": "line",
    "vehicle_id": "vehicle",
    "run_id": "run",
    "dist_from_initial_m": "distance from initial",
    "n_corrections": "balise corrections",
    "n_feature_refused": "feature corrections refused",
    "n_slips_readhered": "slips re-adhered",
    "n_failsafe": "fail-safe events",
    "refusal_reasons": "failed diagnostics (count)",
}

#: Words written as people write them.
WORDS: dict[str, str] = {
    "gps": "GPS",
    "gnss": "GNSS",
    "db": "DB",
    "gis": "GIS",
    "id": "id",
    "ci95": "95 % interval",
    "cn0": "C/N0",
    "kappa": "κ",
    "dir": "direction",
}

#: Unit of a share shown to people.
PERCENT = "%"

_MACHINE = re.compile(r"[a-z][a-z0-9_]*")


@dataclass(frozen=True)
class Display:
    """How a column is shown to people: its label (with its unit) and the factor its values
    are multiplied by (100 for a share, else 1)."""

    label: str
    unit: str
    scale: float = 1.0

    @property
    def percent(self) -> bool:
        """A share shown as a percentage."""
        return self.scale == 100.0


@functools.cache
def declared_units() -> dict[str, str]:
    """Every declared column name with a unit → that unit (:data:`schemas.catalog.ALL_SCHEMAS`)."""
    from schemas.catalog import ALL_SCHEMAS

    out: dict[str, str] = {}
    for table in ALL_SCHEMAS.values():
        for col in table.columns:
            if col.unit:
                out.setdefault(col.name, col.unit)
    return out


def is_share(name: str) -> bool:
    """A fraction 0–1 by the naming rule (``*_share``, ``share_*``)."""
    return name == "share" or name.endswith("_share") or name.startswith("share_")


def _words(stem: str) -> str:
    return " ".join(WORDS.get(w, w) for w in stem.split("_") if w)


@functools.cache
def display(name: str) -> Display:
    """The label, unit and scale of column ``name`` (see the module's rules)."""
    if not _MACHINE.fullmatch(name):
        return Display(name, "")
    if is_share(name):
        return Display(_words(NAMES.get(name, name)), PERCENT, 100.0)  # the value carries its "%"
    stem, unit = name, declared_units().get(name, "")
    for suffix, suffix_unit in SUFFIX_UNITS.items():
        if name.endswith(suffix) and len(name) > len(suffix):
            stem, unit = name[: -len(suffix)], unit or suffix_unit
            break
    parts = name.split("_")
    for k in range(len(parts) - 1, 0, -1):  # lat_new, t_pass: the unit of the declared quantity they qualify
        if unit:
            break
        unit = declared_units().get("_".join(parts[:k]), "")
    if name in NAMES:
        stem = NAMES[name]
    elif stem.startswith("n_"):
        stem = stem[2:]
    words = _words(stem)
    return Display(f"{words} [{unit}]" if unit else words, unit)


def label(name: str) -> str:
    """Column ``name``'s label for people: words, then ``[unit]`` where it has one."""
    return display(name).label
