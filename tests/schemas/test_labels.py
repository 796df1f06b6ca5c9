"""Labels of machine column names (schemas/labels.py): words and the declared unit, shares as %."""

from __future__ import annotations

import pytest

from schemas.catalog import ALL_SCHEMAS
from schemas.labels import SUFFIX_UNITS, declared_units, display, label


@pytest.mark.parametrize(
    ("name", "shown"),
    [
        ("km_m", "km [m]"),
        ("t", "t [s]"),
        ("lat", "lat [deg]"),
        ("lat_new", "lat new [deg]"),
        ("t_pass", "t pass [s]"),
        ("mean_correction_pct", "mean correction [%]"),
        ("distance_km", "distance [km]"),
        ("n_slips", "slips"),
        ("n_corrections", "balise corrections"),
        ("line_code", "line"),
        ("gps_trusted_share", "GPS trusted share"),
        ("share_above_target", "share above target"),
        ("cn0_dbhz", "C/N0 [dB-Hz]"),
        ("track", "track"),
        ("mean %", "mean %"),  # a label already: as given
        ("t from [s]", "t from [s]"),
    ],
)
def test_labels(name: str, shown: str) -> None:
    assert label(name) == shown


def test_a_share_is_shown_times_100_and_nothing_else_is_scaled() -> None:
    assert display("verified_share").scale == 100.0 and display("verified_share").percent
    assert display("mean_correction_pct").scale == 1.0 and display("km_m").scale == 1.0


def test_every_declared_unit_is_the_label_unit_and_no_name_has_two_units() -> None:
    """The declarations are the one source of units: a name declared in two tables has one
    unit, and every declared column's label ends with its unit; a name with a unit suffix
    is declared with that suffix's unit (the naming rule and the declarations agree)."""
    seen: dict[str, set[str]] = {}
    for table in ALL_SCHEMAS.values():
        for col in table.columns:
            seen.setdefault(col.name, set()).add(col.unit)
    assert not {n: u for n, u in seen.items() if len(u - {""}) > 1}
    for name, unit in declared_units().items():
        if name.replace("_", "").isalnum() and name == name.lower():
            assert label(name).endswith(f"[{unit}]"), (name, unit, label(name))
    clashes = []
    for name, units in seen.items():
        for suffix, unit in SUFFIX_UNITS.items():
            if name.endswith(suffix) and units - {""} and unit not in units:
                clashes.append((name, suffix, units))
            if name.endswith(suffix):
                break
    assert not clashes
