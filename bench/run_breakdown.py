"""Where the time of one ``trainpos run`` process goes: phases and the imports inside them.

Run: ``.venv/bin/python bench/run_breakdown.py RUN_DIR --db DB [--out OUT]`` (or through
``bench/bench_run.py --breakdown``). Does what ``trainpos run`` does in this process (the
CLI's own ``app()``), with the pipeline's stages wrapped in timers, and prints per phase the
wall and CPU seconds and the modules first imported inside it (outermost import only, its
nested imports included); the numba dispatcher's compile-or-load-from-cache of each kernel
is a phase of its own. The interpreter's start-up (before this script's first line) is not
seen from inside: ``bench_run.py`` prints the whole process beside it. Never fails on timing.
"""

from __future__ import annotations

import builtins
import sys
import time
from collections import defaultdict
from collections.abc import Callable
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


def _wrap(module: str, attr: str, label: str | None = None) -> None:
    """Replace ``module.attr`` (a function or a class's method as ``Class.method``) by a timed call."""
    mod = __import__(module, fromlist=["_"])
    owner: Any = mod
    *path, name = attr.split(".")
    for p in path:
        owner = getattr(owner, p)
    fn: Callable[..., Any] = getattr(owner, name)

    def timed(*a: Any, **k: Any) -> Any:
        with _Phase(label or attr):
            return fn(*a, **k)

    setattr(owner, name, staticmethod(timed) if isinstance(owner, type) else timed)


#: (module, attribute, label) wrapped before the run: the module a caller imports the name
#: from (``cli.run`` imports inside its function, the pipeline at its module's import).
WRAPPED = [
    ("fieldlogs.config", "load_tree", "settings (load_tree)"),
    ("dbtools.database", "read_network", "read_network (DB, hash)"),
    ("fieldlogs.io", "read_run", "read_run (run.json)"),
    ("fieldlogs.pipeline.outputs", "write_results", "write outputs"),
    ("fieldlogs.pipeline.run", "require_usable", "read streams + usability"),
    ("fieldlogs.pipeline.run", "clean_stream", "clean streams"),
    ("fieldlogs.pipeline.run", "build_cycles", "cycles"),
    ("fieldlogs.pipeline.run", "correct_odometry", "odometry"),
    ("fieldlogs.pipeline.run", "analyse_gps", "GPS matching/analysis"),
    ("fieldlogs.pipeline.run", "FeatureUnit", "feature unit"),
    ("fieldlogs.pipeline.run", "GnssUnit.for_run", "GNSS unit"),
    ("fieldlogs.pipeline.run", "run_aids", "engine (run_aids)"),
    ("fieldlogs.pipeline.run", "summarise", "summary"),
    ("fieldlogs.pipeline.run", "compare_with_truth", "truth comparison"),
]


def main() -> None:
    builtins.__import__ = _timed_import
    with _Phase("import cli.main"):
        from cli.main import app
    # the imports ``trainpos run`` makes inside its function, in its order, each a phase
    for mod in ("dbtools.database", "fieldlogs.config", "fieldlogs.io", "fieldlogs.pipeline.outputs"):
        with _Phase(f"import {mod}"):
            __import__(mod)
    with _Phase("import fieldlogs.pipeline.run"):
        import fieldlogs.pipeline.run  # noqa: F401
    with _Phase("import cli.run"):
        import cli.run  # noqa: F401
    for module, attr, label in WRAPPED:
        _wrap(module, attr, label)
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


if __name__ == "__main__":
    main()
