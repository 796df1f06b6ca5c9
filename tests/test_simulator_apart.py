"""The simulator is its own application (issue 35): it fabricates the data the positioning code
is tested on, so neither may lean on the other.

* (a) nothing of the product imports ``fieldlogs.simulate`` but the modules of
  :data:`SIMULATOR_USERS` (each with its reason), and nothing imports the experiment harnesses
  (``fieldlogs.experiments``: positioning run on simulated data) — tests and benchmarks may;
* (b) everything ``fieldlogs.simulate`` loads — its imports, their imports, and the package
  ``__init__`` files Python runs on the way — is the simulator itself, ``schemas``, ``dbtools``
  or a module of :data:`SHARED` (the world's physics and file formats both sides need), and
  never a module of :data:`POSITIONING` (the code under test).

The import graph is read from the source (``tests/test_import_cycles.py``): every import
counts, lazy and ``TYPE_CHECKING`` ones too. ``dbtools`` never imports ``fieldlogs`` at all
(``tests/test_architecture.py``), so the synthetic networks and the sample's builder, which
need the simulator's alignments, live in ``fieldlogs/simulate/networks/``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import pytest

from tests.test_import_cycles import import_graph

SIMULATOR = "fieldlogs.simulate"
HARNESSES = "fieldlogs.experiments"

#: Product modules that may import the simulator.
SIMULATOR_USERS = {
    "cli.simulate": "the `simulate` command: the simulator's front end",
    "fieldlogs.experiments.gnss": "the GNSS experiment harness: seeded simulated runs through the solver",
}

#: What the simulator may load outside itself, ``schemas`` and ``dbtools`` (a name covers its submodules).
SHARED = {
    "fieldlogs.runs": "run folders: the log streams' one reader and writer, run.json and the vehicle",
    "fieldlogs.recorders": "receiver file formats (simulate --format) and the GPS/UTC time scales",
    "fieldlogs.gnss.constants": "ICD constants and frame columns",
    "fieldlogs.gnss.geodesy": "ECEF, geodetic, ENU",
    "fieldlogs.gnss.ephemeris": "the ICD's broadcast-ephemeris algorithm: where the satellites are",
    "fieldlogs.gnss.atmosphere": "the Klobuchar and Saastamoinen delay models",
    "fieldlogs.gnss.track": "the 3-D track polyline and antenna geometry",
    "fieldlogs.gnss.sbas_tables": "RTCA DO-229's look-up tables and IGP bands",
    "fieldlogs.possession.plan": "the possession plan file's record and writer",
}

#: The code under test: positioning and the applications built on it.
POSITIONING = {
    "fieldlogs.pipeline": "the positioning engine, its aids, odometry, dead reckoning",
    "fieldlogs.gnss": "the GNSS receiver: observables, pre-checks, least squares, constrained solver, FDE, SBAS",
    "fieldlogs.radar": "radar speed estimation",
    "fieldlogs.trackmatch": "track matching of GNSS traces",
    "fieldlogs.survey": "survey extraction from runs",
    "fieldlogs.gisverify": "GIS verification from replayed runs",
    "fieldlogs.possession": "the possession check",
    "fieldlogs.audit": "the fleet audit",
    "fieldlogs.impact": "DB impact on runs",
    "fieldlogs.quality": "log quality checks",
    "fieldlogs.replay": "run replay",
    "fieldlogs.reports": "reports",
    "fieldlogs.experiments": "the experiment harnesses",
    "dbtools.gis.matching": "map-matching of fixes to the grid",
    "dbtools.gis.match_kernel": "map-matching kernel",
    "dbtools.gis.match_numpy": "map-matching kernel",
    "dbtools.gis.verify": "GIS verification statistics",
}


def _under(module: str, names: Iterable[str]) -> bool:
    return any(module == n or module.startswith(n + ".") for n in names)


def _parents(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def loaded_by(graph: Mapping[str, set[str]], start: str) -> set[str]:
    """Every module importing ``start`` loads: imports, theirs, and the packages on each way."""
    seen: set[str] = set()
    todo = [start]
    while todo:
        module = todo.pop()
        for dep in [*graph.get(module, ()), *(p for p in _parents(module) if p in graph)]:
            if dep not in seen:
                seen.add(dep)
                todo.append(dep)
    return seen


def outside_use(graph: Mapping[str, set[str]]) -> list[str]:
    """``module → target`` for every product import of the simulator or a harness not allowed."""
    bad = []
    for module, deps in graph.items():
        if _under(module, [SIMULATOR, HARNESSES]):
            continue
        for dep in sorted(deps):
            if (_under(dep, [SIMULATOR]) and module not in SIMULATOR_USERS) or _under(dep, [HARNESSES]):
                bad.append(f"{module} → {dep}")
    return bad


def _forbidden(module: str) -> bool:
    """Positioning code, or any ``fieldlogs`` module that is neither the simulator nor shared. A
    package whose ``__init__`` runs on the way to a shared module is not (its own imports are
    followed like any other)."""
    if _under(module, [SIMULATOR, *SHARED]) or any(module in _parents(s) for s in SHARED):
        return False
    return module.startswith("fieldlogs") or _under(module, POSITIONING)


def simulator_reach(graph: Mapping[str, set[str]]) -> dict[str, list[str]]:
    """Simulator module → the forbidden modules it loads."""
    out: dict[str, list[str]] = {}
    for module in graph:
        if _under(module, [SIMULATOR]) and (bad := sorted(filter(_forbidden, loaded_by(graph, module)))):
            out[module] = bad
    return out


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph()


def test_nothing_of_the_product_uses_the_simulator(graph: dict[str, set[str]]) -> None:
    bad = outside_use(graph)
    assert not bad, "\n".join(bad)


def test_simulator_loads_no_positioning_code(graph: dict[str, set[str]]) -> None:
    reach = simulator_reach(graph)
    assert not reach, "\n".join(f"{m} loads {', '.join(b)}" for m, b in reach.items())


def test_allow_lists_name_real_modules(graph: dict[str, set[str]]) -> None:
    """An entry that names no module is a rule nobody enforces; a shared module the simulator
    does not load is an exception nobody needs (one not there at all, e.g. a module
    that has moved, is skipped)."""
    missing = [n for n in [*SIMULATOR_USERS, *POSITIONING] if not any(_under(m, [n]) for m in graph)]
    assert not missing, missing
    used = set().union(*(loaded_by(graph, m) for m in graph if _under(m, [SIMULATOR])))
    unused = [n for n in SHARED if any(_under(m, [n]) for m in graph) and not any(_under(m, [n]) for m in used)]
    assert not unused, f"shared but loaded by no simulator module: {unused}"


def test_the_checks_catch_a_violation() -> None:
    """The rules on a made-up graph: a direct import, one through a shared module, one through a
    package ``__init__`` and a product module using the simulator are each found."""
    fake = {
        "fieldlogs.simulate.a": {"fieldlogs.pipeline.engine"},
        "fieldlogs.simulate.b": {"fieldlogs.gnss.geodesy"},
        "fieldlogs.gnss.geodesy": {"fieldlogs.gnss.constrained"},
        "fieldlogs.simulate.c": {"fieldlogs.gnss.sbas.bits"},
        "fieldlogs.gnss.sbas": {"fieldlogs.gnss.corrections"},
        "fieldlogs.gnss.sbas.bits": set(),
        "fieldlogs.simulate.d": {"fieldlogs.gnss.constants"},
        "fieldlogs.gnss.constants": set(),
        "fieldlogs.pipeline.engine": {"fieldlogs.simulate.d"},
        "cli.simulate": {"fieldlogs.simulate.a"},
        "cli.run": {"fieldlogs.experiments.gnss"},
    }
    reach = simulator_reach(fake)
    assert reach["fieldlogs.simulate.a"] == ["fieldlogs.pipeline.engine"]
    assert reach["fieldlogs.simulate.b"] == ["fieldlogs.gnss.constrained"]
    assert "fieldlogs.gnss.corrections" in reach["fieldlogs.simulate.c"]
    assert "fieldlogs.simulate.d" not in reach
    assert outside_use(fake) == [
        "fieldlogs.pipeline.engine → fieldlogs.simulate.d",
        "cli.run → fieldlogs.experiments.gnss",
    ]
