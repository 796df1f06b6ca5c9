"""GIS height rules (``dbtools.rules.heights``): the synthetic network's heights are clean;
one height off, a gradient too steep, a column partly empty or an orthometric datum each give
exactly their finding, and nearly-broken heights give none."""

from __future__ import annotations

import numpy as np
import pytest

from dbtools.gis.geometry import Projector
from dbtools.network import Network
from dbtools.rules.common import Locator
from dbtools.rules.config import ValidationConfig
from dbtools.rules.heights import check_heights
from dbtools.validate import validate_network
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from schemas.enums import Severity


@pytest.fixture(scope="module")
def clean() -> Network:
    return build_network([demo_line()], Projector(9))


@pytest.fixture
def net(clean: Network) -> Network:
    return Network({k: v.copy() for k, v in clean.tables.items()}, origin="test", meta=dict(clean.meta))


def _rules(net: Network) -> list[tuple[str, str]]:
    return [(f.rule, str(f.severity)) for f in check_heights(net.gis, net.meta, ValidationConfig(), Locator())]


def _track_rows(net: Network, track: str = "D") -> np.ndarray:
    g = net.gis
    return np.flatnonzero((g["track"] == track).to_numpy())[np.argsort(g.loc[g["track"] == track, "km_m"].to_numpy())]


def test_clean_heights_have_no_finding(net: Network) -> None:
    assert net.gis["height_m"].notna().all()
    assert _rules(net) == []
    assert not [f for f in validate_network(net) if f.rule.startswith("gis.height")]


def test_no_heights_at_all_is_no_finding(net: Network) -> None:
    net.gis["height_m"] = np.nan
    assert _rules(net) == []


def test_a_partly_empty_height_column_is_an_error_once_per_track(net: Network) -> None:
    rows = _track_rows(net)
    net.gis.loc[rows[[10, 11, 40]], "height_m"] = np.nan
    found = check_heights(net.gis, net.meta, ValidationConfig(), Locator())
    partial = [f for f in found if f.rule == "gis.height_partial"]
    assert len(partial) == 1 and partial[0].severity == Severity.ERROR
    assert partial[0].keys["track"] == "D" and partial[0].value == len(rows) - 3


def test_a_spike_is_a_curvature_error_and_a_small_bump_passes(net: Network) -> None:
    rows = _track_rows(net)
    net.gis.loc[rows[50], "height_m"] += 0.01  # 1 cm: R = 20² / (2·0.01) = 20 km
    assert _rules(net) == []
    net.gis.loc[rows[50], "height_m"] += 0.99  # 1 m: R = 200 m
    rules = _rules(net)
    assert ("gis.height_curvature", "error") in rules
    # the grades next to it are 50 ‰: a warning, not an error
    assert ("gis.height_grade", "warning") in rules and ("gis.height_grade", "error") not in rules


def test_a_steep_stretch_is_one_grade_finding(net: Network) -> None:
    rows = _track_rows(net)
    h = net.gis["height_m"].to_numpy(dtype=float).copy()
    # 150 ‰ over 10 steps (a 30 m rise over 200 m), then level again
    rise = np.clip(np.arange(len(rows)) - 100, 0, 10) * 20.0 * 0.15
    h[rows] = h[rows] + rise
    net.gis["height_m"] = h
    grade = [f for f in check_heights(net.gis, net.meta, ValidationConfig(), Locator()) if f.rule == "gis.height_grade"]
    assert len(grade) == 1 and grade[0].severity == Severity.ERROR
    assert grade[0].value == pytest.approx(150.0, abs=15.0)  # + the line's own grade (≤ 15 ‰)


def test_orthometric_heights_are_a_warning(net: Network) -> None:
    net.meta.update(height_datum="orthometric", geoid_model="GSIGEO2011")
    found = check_heights(net.gis, net.meta, ValidationConfig(), Locator())
    assert [(f.rule, f.severity) for f in found] == [("gis.height_datum", Severity.WARNING)]
    assert "GSIGEO2011" in found[0].message


def test_a_kilometrage_break_is_no_step(net: Network) -> None:
    rows = _track_rows(net)
    km = net.gis["km_m"].to_numpy(dtype=float).copy()
    km[rows[200:]] += 1000.0  # km jumps by 1 km: no grade between the two points
    net.gis["km_m"] = km
    h = net.gis["height_m"].to_numpy(dtype=float).copy()
    h[rows[200:]] += 5.0  # would be 250 ‰ over 20 m if it were a step
    net.gis["height_m"] = h
    assert _rules(net) == []


def test_the_grid_index_of_a_whole_frame_gives_the_same_findings(net: Network) -> None:
    """With the frame's grid index (every row a point, in its order) the rules take its track
    ids as the rows' keys instead of factorizing the frame: the same findings, in order."""
    from dbtools.gis.index import GridIndex
    from dbtools.network import canonical
    from schemas.tables import GIS

    rows = _track_rows(net)
    net.gis.loc[rows[[10, 11, 40]], "height_m"] = np.nan  # partial
    net.gis.loc[rows[100], "height_m"] += 0.8  # a spike
    net.gis.loc[rows[200:260], "height_m"] += np.linspace(0.0, 4.0, 60)  # a steep stretch
    gis = canonical(GIS, net.gis)
    grid = GridIndex(gis)
    assert grid.whole_frame
    cfg = ValidationConfig(max_findings_per_rule=2)
    plain = check_heights(gis, net.meta, cfg, Locator())
    assert {f.rule for f in plain} == {"gis.height_partial", "gis.height_curvature", "gis.height_grade"}
    assert check_heights(gis, net.meta, cfg, Locator(), grid) == plain
    shuffled = gis.sample(frac=1.0, random_state=1)  # not the grid's frame: read as before
    assert check_heights(shuffled, net.meta, cfg, Locator(), GridIndex(shuffled)) == plain


def test_blocks_of_any_size_give_the_same_findings(net: Network, monkeypatch: pytest.MonkeyPatch) -> None:
    """Grade and vertical radius computed ``BLOCK`` steps at a time (a spike and a steep
    stretch across block ends) give the findings of one block."""
    import dbtools.gis.index as index_mod

    rows = _track_rows(net)
    net.gis.loc[rows[[100, 107]], "height_m"] += 0.8
    net.gis.loc[rows[200:260], "height_m"] += np.linspace(0.0, 4.0, 60)
    whole = check_heights(net.gis, net.meta, ValidationConfig(), Locator())
    assert {f.rule for f in whole} == {"gis.height_curvature", "gis.height_grade"}
    for block in (7, 50):
        monkeypatch.setattr(index_mod, "BLOCK", block)
        assert check_heights(net.gis, net.meta, ValidationConfig(), Locator()) == whole
