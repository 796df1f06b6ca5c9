"""Where the time of one ``trainpos run`` process goes: phases and the imports inside them.

Run: ``.venv/bin/python bench/run_breakdown.py RUN_DIR --db DB --out OUT [--force]`` (or through
``bench/bench_run.py --breakdown``). Does what ``trainpos run`` does in this process (the
CLI's own ``app()``), with the pipeline's stages wrapped in timers, and prints per phase the
wall and CPU seconds and the modules first imported inside it (outermost import only, its
nested imports included); the numba dispatcher's compile-or-load-from-cache of each kernel
is a phase of its own. The interpreter's start-up (before this script's first line) is not
seen from inside: ``bench_run.py`` prints the whole process beside it. Never fails on timing;
an entry of :data:`WRAPPED` that no longer resolves stops it before the run, naming the entry,
and a stage never called is listed after the table.
"""

from __future__ import annotations

import builtins
import importlib
import inspect
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

T0_WALL, T0_CPU = time.perf_counter(), time.process_time()
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

_phases: list[tuple[str, float, float]] = []  # (label, wall s, CPU s) of the leaf phases
_stack: list[list[float]] = []  # per open phase: [wall start, CPU start, child wall, child CPU]
_imports: dict[str, dict[str, float]] = defaultdict(dict)  # phase → module → CPU s
_children: dict[tuple[str, str], dict[str, float]] = defaultdict(dict)  # (phase, module) → its imports
_depth = 0
_outer = ""
_orig_import = builtins.__import__


def _current() -> str:
    return _labels[-1] if _labels else "(outside any phase)"


_labels: list[str] = []


def _timed_import(name: str, globals: Any = None, locals: Any = None, fromlist: Any = (), level: int = 0) -> Any:
    """``__import__`` timing the outermost import of a module not yet loaded."""
    global _depth, _outer
    if _depth > 1 or (level == 0 and name in sys.modules and not fromlist):
        return _orig_import(name, globals, locals, fromlist, level)
    before = len(sys.modules)
    _depth += 1
    c0 = time.process_time()
    outer = _outer
    if _depth == 1:
        _outer = name
    try:
        return _orig_import(name, globals, locals, fromlist, level)
    finally:
        _depth -= 1
        dt = time.process_time() - c0
        if len(sys.modules) > before and dt > 0.0005:
            if _depth == 0:
                mods = _imports[_current()]
                mods[name] = mods.get(name, 0.0) + dt
            else:
                kids = _children[(_current(), _outer)]
                kids[name] = kids.get(name, 0.0) + dt
        if _depth == 0:
            _outer = outer
        _patch_numba()


def _patch_numba() -> None:
    """Time each numba dispatcher's first compile-or-cache-load as a phase of its own."""
    disp = sys.modules.get("numba.core.dispatcher")
    if disp is None or getattr(disp, "_bench_patched", False):
        return
    disp._bench_patched = True  # type: ignore[attr-defined]
    orig = disp.Dispatcher._compile_for_args

    def compile_for_args(self: Any, *args: Any, **kws: Any) -> Any:
        with _Phase(f"numba load/compile {self.py_func.__name__}"):
            return orig(self, *args, **kws)

    disp.Dispatcher._compile_for_args = compile_for_args


class _Phase:
    def __init__(self, label: str) -> None:
        self.label = label

    def __enter__(self) -> None:
        _labels.append(self.label)
        _stack.append([time.perf_counter(), time.process_time(), 0.0, 0.0])

    def __exit__(self, *exc: object) -> None:
        w0, c0, cw, cc = _stack.pop()
        w, c = time.perf_counter() - w0, time.process_time() - c0
        _labels.pop()
        _phases.append((self.label, w - cw, c - cc))  # self time: children are phases too
        if _stack:
            _stack[-1][2] += w
            _stack[-1][3] += c


@dataclass(frozen=True)
class Stage:
    """A stage timed as a phase: ``module.attr`` (a function, a class, or ``Class.method``)."""

    module: str
    attr: str
    label: str


@dataclass(frozen=True)
class Resolved:
    """Where a stage's name is looked up (module or class), the name, and what it is now."""

    stage: Stage
    owner: Any
    name: str
    target: Callable[..., Any]
    bound: bool  # a classmethod/staticmethod: called through the class, never given ``self``


class StaleStage(LookupError):
    """A :data:`WRAPPED` entry that no longer names a callable (the code moved on)."""


def resolve(stage: Stage) -> Resolved:
    """The callable a stage names; :class:`StaleStage` saying which part is missing."""
    try:
        owner: Any = importlib.import_module(stage.module)
    except ImportError as exc:
        raise StaleStage(f"{stage.module}.{stage.attr}: module {stage.module!r} not importable ({exc})") from exc
    *path, name = stage.attr.split(".")
    for p in path:
        if not hasattr(owner, p):
            raise StaleStage(f"{stage.module}.{stage.attr}: {owner.__name__} has no attribute {p!r}")
        owner = getattr(owner, p)
    if not hasattr(owner, name):
        raise StaleStage(f"{stage.module}.{stage.attr}: {owner.__name__} has no attribute {name!r}")
    raw = inspect.getattr_static(owner, name)
    bound = isinstance(owner, type) and isinstance(raw, classmethod | staticmethod)
    target = getattr(owner, name) if bound or not isinstance(owner, type) else raw
    if not callable(target):
        raise StaleStage(f"{stage.module}.{stage.attr}: not callable ({type(target).__name__})")
    return Resolved(stage, owner, name, target, bound)


def resolve_all(stages: Iterable[Stage]) -> list[Resolved]:
    """Every stage resolved, or SystemExit naming each stale entry (before anything runs)."""
    found, stale = [], []
    for stage in stages:
        try:
            found.append(resolve(stage))
        except StaleStage as exc:
            stale.append(f"  {stage.label!r}: {exc}")
    if stale:
        raise SystemExit(
            "bench/run_breakdown.py: stale WRAPPED entries (find where each stage now lives in "
            "fieldlogs/pipeline/ and update WRAPPED):\n" + "\n".join(stale)
        )
    return found


_calls: dict[str, int] = defaultdict(int)  # label → calls of its wrapped stages


def _wrap(r: Resolved) -> None:
    """Replace the resolved name by a timed call of what it named."""
    fn, label = r.target, r.stage.label

    def timed(*a: Any, **k: Any) -> Any:
        _calls[label] += 1
        with _Phase(label):
            return fn(*a, **k)

    _calls.setdefault(label, 0)
    setattr(r.owner, r.name, staticmethod(timed) if r.bound else timed)


#: Stages wrapped before the run, each in the module a caller looks the name up in (``cli.run``
#: imports inside its function, the pipeline modules at their import). A stage never called in
#: the run is reported as such: a name that still resolves but lost its caller.
WRAPPED = (
    Stage("fieldlogs.config", "load_tree", "settings (load_tree)"),
    Stage("dbtools.database", "read_network", "read_network (DB, hash)"),
    Stage("fieldlogs.runs.handle", "read_run", "read_run (run.json)"),
    Stage("fieldlogs.runs.handle", "Run.stream", "read streams"),
    Stage("fieldlogs.pipeline.windows", "run_pipeline", "pipeline (rest)"),
    Stage("fieldlogs.pipeline.run", "require_usable", "usability check"),
    Stage("fieldlogs.pipeline.run", "clean_stream", "clean streams"),
    Stage("fieldlogs.pipeline.run", "clock_offsets", "clock check"),
    Stage("fieldlogs.pipeline.run", "build_cycles", "cycles"),
    Stage("fieldlogs.pipeline.run", "correct_odometry", "odometry"),
    Stage("fieldlogs.pipeline.run", "analyse_gps", "GPS matching/analysis"),
    Stage("fieldlogs.pipeline.run", "FeatureUnit", "feature unit"),
    Stage("fieldlogs.pipeline.run", "GnssUnit.for_run", "GNSS unit"),
    Stage("fieldlogs.pipeline.wheelscale", "checked_solution", "balise checks (rest)"),
    Stage("fieldlogs.pipeline.consistency", "run_aids", "engine (run_aids)"),
    Stage("fieldlogs.pipeline.engine", "positions_frame", "positions frame"),
    Stage("fieldlogs.pipeline.run", "summarise", "summary"),
    Stage("fieldlogs.pipeline.run", "compare_with_truth", "truth comparison"),
    Stage("fieldlogs.pipeline.outputs", "ResultsWriter.add_positions", "write positions"),
    Stage("fieldlogs.pipeline.outputs", "ResultsWriter.finish", "write events + summary"),
)


#: The imports ``trainpos run`` makes inside its function (``cli/run.py``), in its order, then the
#: pipeline and the CLI module itself: each a phase of its own.
RUN_IMPORTS = (
    "dbtools.database",
    "fieldlogs.config",
    "fieldlogs.runs.handle",
    "fieldlogs.pipeline.outputs",
    "fieldlogs.pipeline.windows",
    "fieldlogs.pipeline.run",
    "cli.run",
)


def main() -> None:
    """Time one ``trainpos run`` (this script's arguments) phase by phase; the table to stderr."""
    builtins.__import__ = _timed_import
    with _Phase("import cli.main"):
        from cli.main import app
    # the imports ``trainpos run`` makes inside its function, in its order, each a phase
    for mod in RUN_IMPORTS:
        with _Phase(f"import {mod}"):
            __import__(mod)
    for r in resolve_all(WRAPPED):
        _wrap(r)
    with _Phase("CLI parse + run (rest)"):
        try:
            app(["run", *sys.argv[1:]])
        except SystemExit as exc:
            if exc.code:
                raise
    wall, cpu = time.perf_counter() - T0_WALL, time.process_time() - T0_CPU
    builtins.__import__ = _orig_import
    report(wall, cpu)


def report(wall: float, cpu: float) -> None:
    """One line per phase (repeated phases summed, in first-seen order)."""
    totals: dict[str, list[float]] = {}
    for label, w, c in _phases:
        t = totals.setdefault(label, [0.0, 0.0])
        t[0] += w
        t[1] += c
    print(f"{'phase':<36} {'wall s':>7} {'CPU s':>7}  imports first made in it, CPU s [their imports]", file=sys.stderr)
    for label, (w, c) in totals.items():
        parts = []
        for m, dt in sorted(_imports.get(label, {}).items(), key=lambda kv: -kv[1]):
            if dt < 0.01:
                continue
            kids = sorted(_children.get((label, m), {}).items(), key=lambda kv: -kv[1])
            sub = ", ".join(f"{k} {v:.2f}" for k, v in kids if v >= 0.01)
            parts.append(f"{m} {dt:.2f}" + (f" [{sub}]" if sub else ""))
        print(f"{label:<36} {w:7.3f} {c:7.3f}  {'; '.join(parts)}", file=sys.stderr)
    print(f"{'total (from the script first line)':<36} {wall:7.3f} {cpu:7.3f}", file=sys.stderr)
    idle = [label for label, n in _calls.items() if n == 0]
    if idle:
        print(f"stages never called in this run: {', '.join(idle)}", file=sys.stderr)


if __name__ == "__main__":
    main()
