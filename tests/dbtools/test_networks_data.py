"""The committed hand-made networks (tests/data/networks) are what their generator makes,
and their geometry is what its docstring says."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import pytest

from dbtools.rules.track_geometry import track_geometry
from dbtools.sources import read_source_set
from dbtools.topology import all_tracks, centreline

HERE = Path(__file__).resolve().parents[1] / "data" / "networks"


def generator() -> ModuleType:
    """The generator script as a module."""
    spec = importlib.util.spec_from_file_location("make_networks", HERE / "make_networks.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up while the class is made
    spec.loader.exec_module(mod)
    return mod


def test_committed_files_equal_a_fresh_generation() -> None:
    fresh = generator().generate()
    assert set(fresh) == {p.name for p in HERE.iterdir() if p.is_dir() and not p.name.startswith("_")}
    for name, files in fresh.items():
        assert {p.name for p in (HERE / name).iterdir()} == set(files), name
        for fname, text in files.items():
            assert (HERE / name / fname).read_text(encoding="utf-8") == text, f"{name}/{fname}"


def test_crossover_radius_gives_the_extent() -> None:
    """e = 2·R·tan(α/2) + d·cot α (generator doc): R for 60 m, then the drawn path ends 60 m on, 4 m aside."""
    g = generator()
    r = g.radius_for_extent(60.0, 4.0, 10.0)
    x, y, h = g.crossover_path(0.0, 0.0, 4.0, 10.0, r, left=True).at(1e9)
    assert (x, y, h) == pytest.approx((60.0, 4.0, 0.0), abs=1e-9)
    assert r == pytest.approx(10.0 / math.tan(math.atan(0.1) / 2), rel=1e-12)  # d·cot α = 40 m


@pytest.mark.parametrize("name", ["junction", "crossover", "station4", "double_slip"])
def test_lengths_are_true_on_the_ellipsoid(name: str) -> None:
    """Every track's stated length equals its geodesic centreline length within 5 cm (the
    20 m chords of a 190 m curve lose L³/24R² ≈ 9 mm each)."""
    net, findings = read_source_set(HERE / name)
    assert findings == []
    tracks = all_tracks(net)
    geo = track_geometry(net, tracks)
    assert (abs(tracks["length_m"] - geo["geo_length_m"]) < 0.05).all()


@pytest.mark.parametrize("name", ["junction", "crossover", "station4", "double_slip"])
def test_vectorised_ends_agree_with_centreline(name: str) -> None:
    """track_geometry (all tracks at once) places each end where dbtools.topology.centreline
    (one track at a time) has its first/last point: the ends lie on the 20 m grid here."""
    net, _ = read_source_set(HERE / name)
    tracks = all_tracks(net)
    geo = track_geometry(net, tracks)
    for i in range(len(tracks)):
        c = centreline(net, tracks.iloc[i])
        assert geo["lat_begin"].iloc[i] == pytest.approx(c.lat[0], abs=1e-9)
        assert geo["lon_begin"].iloc[i] == pytest.approx(c.lon[0], abs=1e-9)
        assert geo["lat_end"].iloc[i] == pytest.approx(c.lat[-1], abs=1e-9)
        assert geo["lon_end"].iloc[i] == pytest.approx(c.lon[-1], abs=1e-9)
