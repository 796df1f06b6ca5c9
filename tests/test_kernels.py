"""The numba kernels are cached on disk and compiled ahead (issue 21): every ``@njit`` has
``cache=True``, and each kernel's ``warm()`` (run by ``make`` at install) compiles exactly
the specialisation the real code calls, so no command compiles on its first use."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from dbtools.gis import match_kernel
from dbtools.gis.geometry import Projector
from dbtools.gis.matching import track_index_for
from dbtools.synthetic.network import build_network, demo_line
from fieldlogs.simulate import radar
from fieldlogs.simulate.scenario import RadarIfCfg

ROOT = Path(__file__).resolve().parents[1]


def _njit_calls() -> list[tuple[str, ast.Call | ast.Name | ast.Attribute]]:
    found = []
    for path in sorted(p for pkg in ("cli", "dbtools", "fieldlogs", "schemas") for p in (ROOT / pkg).rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if "numba" not in text:
            continue
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                for dec in node.decorator_list:
                    target = dec.func if isinstance(dec, ast.Call) else dec
                    name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
                    if name in ("njit", "jit", "vectorize", "guvectorize", "cfunc"):
                        found.append((f"{path.relative_to(ROOT)}:{node.name}", dec))
    return found


def test_every_numba_kernel_is_cached_on_disk() -> None:
    kernels = _njit_calls()
    assert len(kernels) >= 4  # the matching kernel and its two helpers, the radar echo sum
    for where, dec in kernels:
        cached = isinstance(dec, ast.Call) and any(
            k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True for k in dec.keywords
        )
        assert cached, f"{where}: @njit without cache=True"


def test_matching_kernel_warm_covers_the_real_calls() -> None:
    match_kernel.warm()
    warmed = list(match_kernel.match_kernel.signatures)
    assert len(warmed) == 1
    index = track_index_for(build_network([demo_line()], Projector(9)))
    m = index.match_xy(index.x[::7] + 1.5, index.y[::7] - 2.0)
    assert len(m) and (m["distance_m"] <= 15.0).all()
    assert list(match_kernel.match_kernel.signatures) == warmed  # nothing compiled for the real call


def test_radar_kernel_warm_covers_the_real_calls() -> None:
    radar.warm()
    warmed = list(radar._echo_kernel.signatures)
    assert len(warmed) == 1
    cfg = RadarIfCfg()
    sigma = np.linspace(0.0, 5.0, 50)
    g = radar.Ground(sigma, np.zeros(50), np.zeros(50), np.ones(50, dtype=np.complex128))
    z = radar.echo(g, np.array([0.5, 1.0]), np.full(2, cfg.height_m), 1, cfg.f0_hz, cfg, radar.view(cfg))
    assert z.shape == (2,) and np.isfinite(z).all() and math.isfinite(float(np.abs(z).sum()))
    assert list(radar._echo_kernel.signatures) == warmed


@pytest.mark.parametrize("module", ["dbtools/gis/matching.py", "fieldlogs/simulate/simulator.py"])
def test_modules_that_read_a_db_or_simulate_do_not_import_numba(module: str) -> None:
    """numba is imported by the kernel modules only, when a kernel is first called."""
    tree = ast.parse((ROOT / module).read_text(encoding="utf-8"))
    top = [n for n in tree.body if isinstance(n, ast.Import | ast.ImportFrom)]
    names = {a.name for n in top if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module or "" for n in top if isinstance(n, ast.ImportFrom)}
    assert not {n for n in names if n.split(".")[0] == "numba" or n.endswith("match_kernel")}
