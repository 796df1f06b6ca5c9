"""Possession-check report: the timeline plot and one self-contained HTML page
(:mod:`dbtools.pagekit`).

The timeline (matplotlib, headless Agg) shows per run km against time: the governing
possession's section as a band, the on-rail (PTO on) periods shaded, the km estimate with
its uncertainty band, the map-matched fixes (trusted / not), the up/down decision and
every alarm and notice. The HTML embeds it as a PNG ``data:`` URI (no script, no external
resource), so the file works offline and can be mailed; its legend is every alarm and
notice type with its meaning (:data:`schemas.enums.ALARM_MEANING`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from dbtools import pagekit as kit
from fieldlogs.possession.results import Alarm, PeriodResult, RunCheck
from schemas.enums import ALARM_MEANING, AlarmType, NoticeType

if TYPE_CHECKING:
    from matplotlib.axes import Axes

#: Plotted points per second of the estimate (the evaluation grid is 10 Hz).
PLOT_HZ = 1.0
#: Columns of the alarm and notice tables.
ALARM_HEADER = ("type", "t [s]", "time", "km [m]", "track", "work_no", "evidence")


class _Labels:
    """Each legend label once."""

    def __init__(self) -> None:
        self.seen: set[str] = set()

    def __call__(self, label: str) -> str | None:
        if label in self.seen:
            return None
        self.seen.add(label)
        return label


def _draw_period(ax: Axes, p: PeriodResult, once: Callable[[str], str | None]) -> tuple[float, float]:
    """One on-rail period: shading, sections, km band, fixes, decisions; the km range drawn."""
    lo, hi = np.inf, -np.inf
    ax.axvspan(p.t_on, p.t_off, color="tab:green", alpha=0.07, label=once("on rail (PTO on)"))
    for t0, t1, work, kf, kt in p.timeline.sections:
        ax.fill_between([t0, t1], kf, kt, color="tab:blue", alpha=0.12, label=once("possession section"))
        ax.text(t0, kt, f" {work}", fontsize=8, va="bottom", color="tab:blue")
        lo, hi = min(lo, kf), max(hi, kt)
    tl = p.timeline
    dt = float(np.median(np.diff(tl.t))) if tl.t.size > 1 else 1.0
    step = max(round(1.0 / PLOT_HZ / max(dt, 1e-3)), 1)
    t, km, u = tl.t[::step], tl.km[::step], tl.u[::step]
    ok = np.isfinite(km)
    if ok.any():
        ax.fill_between(t, km - u, km + u, where=ok, color="tab:orange", alpha=0.3, label=once("km ± uncertainty"))
        ax.plot(t, km, color="tab:orange", lw=1.2, label=once("km estimate"))
        lo, hi = min(lo, float(np.nanmin(km))), max(hi, float(np.nanmax(km)))
    tr = tl.fix_trusted
    ax.plot(tl.fix_t[tr], tl.fix_km[tr], ".", ms=2.5, color="k", label=once("trusted fixes"))
    ax.plot(tl.fix_t[~tr], tl.fix_km[~tr], "x", ms=3, color="0.55", label=once("other fixes"))
    for d in p.decisions:
        ax.axvline(d.t, color="tab:purple", lw=1, ls="--", label=once("up/down decision"))
        ax.text(d.t, 0.98, f" {d.track}", transform=ax.get_xaxis_transform(), color="tab:purple", va="top")
    return lo, hi


def timeline_png(check: RunCheck) -> bytes:
    """km against t for one run (module docstring)."""
    fig, ax = kit.pyplot().subplots(figsize=(10, 5))
    once = _Labels()
    lo, hi = np.inf, -np.inf
    for p in check.periods:
        p_lo, p_hi = _draw_period(ax, p, once)
        lo, hi = min(lo, p_lo), max(hi, p_hi)
    for a in check.alarms:
        _mark(ax, a, "X", "red", once("alarm"))
    for n in check.notices:
        _mark(ax, n, "^", "darkorange", once("notice"))
    if np.isfinite(lo):
        pad = max(0.1 * (hi - lo), 50.0)
        ax.set_ylim(lo - pad, hi + pad)
    else:
        ax.text(0.5, 0.5, "no position", ha="center", va="center", transform=ax.transAxes, color="0.4")
    ax.set_xlabel(f"t [s] since {check.start_time.isoformat()}")
    ax.set_ylabel("km [m]")
    ax.ticklabel_format(axis="y", useOffset=False, style="plain")
    ax.set_title(f"Run {check.run_id}: possession check")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return kit.png(fig)


def _mark(ax: Axes, a: Alarm, marker: str, color: str, label: str | None) -> None:
    y = a.km_m if a.km_m is not None else float(np.mean(ax.get_ylim()))
    ax.plot([a.t], [y], marker, color=color, ms=9, label=label, zorder=5)
    ax.annotate(a.type.value, (a.t, y), textcoords="offset points", xytext=(4, 6), fontsize=7, color=color)


def _text(v: Any) -> str:
    """A JSON value as cell text (evidence dicts as ``key: value`` pairs)."""
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.2f}"
    if isinstance(v, dict):
        return "; ".join(f"{k}: {_text(x)}" for k, x in v.items())
    return str(v)


def _rows(items: list[dict[str, Any]], status: kit.Status) -> str:
    if not items:
        return kit.paragraph("none", kit.Status.NOTE)
    keys = ("t", "time", "km_m", "track", "work_no", "evidence")
    rows = [[kit.Cell(_text(a["type"]), status.value), *(kit.Cell(_text(a[k])) for k in keys)] for a in items]
    return kit.table(ALARM_HEADER, rows, cls="text", scroll=False)


def _legend() -> str:
    alarms = {t.value: ALARM_MEANING[t] for t in AlarmType}
    notices = {t.value: ALARM_MEANING[t] for t in NoticeType}
    return kit.legend(alarms, "Alarms:") + kit.legend(notices, "Notices:")


def _run_parts(c: RunCheck) -> list[str]:
    j = c.to_json()
    dec = j["track_decision"]
    dec_txt = (
        f"{dec['line_code']} / {dec['track']} at t = {dec['t']:.1f} s ({dec['after_on_rail_s']:.1f} s after PTO on)"
        if dec
        else "undecided"
    )
    tacho = "used" if c.tacho["used"] else str(c.tacho["note"])
    on = "; ".join(f"{p['time_on']} – {p['time_off']} (t {p['t_on']:.0f}–{p['t_off']:.0f} s)" for p in j["on_rail"])
    summary = [
        ("run", c.run),
        ("possessions", ", ".join(c.possessions) or "none"),
        ("on rail", on or "never"),
        ("track decision", dec_txt),
        ("tacho", tacho),
    ]
    alt = f"Timeline of run {c.run_id}"
    caption = (
        f"{alt}: km against time, section band, on-rail periods, km ± uncertainty, fixes, decision, "
        "alarms (red) and notices (orange)."
    )
    return [
        kit.heading(c.run_id),
        kit.key_value_table(summary, code=("run",)),
        kit.section("Alarms", _rows(j["alarms"], kit.Status.ALARM), level=3),
        kit.section("Notices", _rows(j["notices"], kit.Status.NOTE), level=3),
        kit.figure(timeline_png(c), alt, caption),
    ]


def render_html(
    checks: list[RunCheck], *, plan: str = "", db: str = "", failed: list[tuple[str, str]] | None = None
) -> str:
    """Every run's summary, alarms, notices and timeline as one HTML string (and the runs
    that could not be checked, with their errors)."""
    n_alarms = sum(len(c.alarms) for c in checks)
    status = kit.Status.ALARM if n_alarms else kit.Status.OK
    parts = [
        f"<p>Plan {kit.code(plan)}, onboard DB {kit.code(db)}, {len(checks)} run(s), "
        f"{kit.badge(f'{n_alarms} alarm(s)', status)}; {kit.generated()}.</p>",
        _legend(),
    ]
    if failed:
        items = "".join(f"<li>{kit.code(run)}: {kit.escape(err)}</li>" for run, err in failed)
        parts.append(kit.section("Runs that could not be checked", f"<ul>{items}</ul>"))
    for c in checks:
        parts += _run_parts(c)
    n_failed = len(failed or [])
    unchecked = f"; {n_failed} run(s) could not be checked" if n_failed else ""
    if n_alarms:
        runs = sum(1 for c in checks if c.alarms)
        v = kit.Verdict(f"Alarm: {n_alarms} alarm(s) in {runs} of {len(checks)} run(s){unchecked}.", kit.Status.ALARM)
    elif n_failed or not checks:
        v = kit.Verdict(f"Incomplete: no alarm in {len(checks)} run(s) checked{unchecked}.", kit.Status.CAUTION)
    else:
        v = kit.Verdict(f"Passed: no alarm in {len(checks)} run(s).", kit.Status.OK)
    return kit.page("trainpos possession check", *parts, heading_text="Possession check", verdict=v)
