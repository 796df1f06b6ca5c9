"""Possession-check report: the timeline plot and one self-contained HTML page.

The timeline (matplotlib, headless Agg) shows per run km against time: the governing
possession's section as a band, the on-rail (PTO on) periods shaded, the km estimate with
its uncertainty band, the map-matched fixes (trusted / not), the up/down decision and
every alarm and notice. The HTML embeds it as a PNG ``data:`` URI (no script, no external
resource), so the file works offline and can be mailed.
"""

from __future__ import annotations

import base64
import html
import io
from datetime import UTC, datetime
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from fieldlogs.possession.results import Alarm, RunCheck

CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:2em;color:#222;max-width:1400px}
table{border-collapse:collapse;margin:1em 0;font-size:13px}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f0f0f0}.alarm{color:#b00;font-weight:bold}.ok{color:#070;font-weight:bold}.note{color:#666}
figure{margin:1.5em 0}img{max-width:100%}code{font-size:12px}
"""
#: Plotted points per second of the estimate (the evaluation grid is 10 Hz).
PLOT_HZ = 1.0


def timeline_png(check: RunCheck) -> bytes:
    """km against t for one run (module docstring)."""
    fig, ax = plt.subplots(figsize=(10, 5))
    labelled: set[str] = set()

    def once(label: str) -> str | None:
        if label in labelled:
            return None
        labelled.add(label)
        return label

    lo, hi = np.inf, -np.inf
    for p in check.periods:
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
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=96, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _mark(ax: Any, a: Alarm, marker: str, color: str, label: str | None) -> None:
    y = a.km_m if a.km_m is not None else float(np.mean(ax.get_ylim()))
    ax.plot([a.t], [y], marker, color=color, ms=9, label=label, zorder=5)
    ax.annotate(a.type, (a.t, y), textcoords="offset points", xytext=(4, 6), fontsize=7, color=color)


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.2f}"
    if isinstance(v, dict):
        return "<br>".join(f"{html.escape(str(k))}: {_cell(x)}" for k, x in v.items())
    return html.escape(str(v))


def _rows(items: list[dict[str, Any]], cls: str) -> str:
    if not items:
        return "<p class='note'>none</p>"
    head = "".join(f"<th>{c}</th>" for c in ("type", "t [s]", "time", "km [m]", "track", "work_no", "evidence"))
    body = "".join(
        f"<tr><td class='{cls}'>{_cell(a['type'])}</td><td>{_cell(a['t'])}</td><td>{_cell(a['time'])}</td>"
        f"<td>{_cell(a['km_m'])}</td><td>{_cell(a['track'])}</td><td>{_cell(a['work_no'])}</td>"
        f"<td>{_cell(a['evidence'])}</td></tr>"
        for a in items
    )
    return f"<table><tr>{head}</tr>{body}</table>"


def render_html(checks: list[RunCheck], *, plan: str = "", db: str = "") -> str:
    """Every run's summary, alarms, notices and timeline as one HTML string."""
    n_alarms = sum(len(c.alarms) for c in checks)
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'><title>trainpos possession check</title>"
        f"<style>{CSS}</style></head><body><h1>Possession check</h1>",
        f"<p>Plan <code>{html.escape(plan)}</code>, onboard DB <code>{html.escape(db)}</code>, {len(checks)} run(s), "
        f"<span class='{'alarm' if n_alarms else 'ok'}'>{n_alarms} alarm(s)</span>; "
        f"generated {datetime.now(UTC):%Y-%m-%d %H:%M} UTC.</p>",
        "<p class='note'>Alarms: wrong_track (on rail on a track no possession covers, once decided), "
        "wrong_track_suspected (undecided 120 s after PTO on, the evidence leaning to another track), overrun "
        "(km ± uncertainty, at most 15 m, not inside the section), released_on_rail, not_started. Notices: "
        "approaching_end (30 m), overrun_possible (the wider band leaves the section: judgement held), "
        "track_undecided (no decision 120 s after PTO on), crossover, position_uncertain, "
        "position_undetermined.</p>",
    ]
    for c in checks:
        j = c.to_json()
        dec = j["track_decision"]
        dec_txt = (
            f"{dec['line_code']} / {dec['track']} at t = {dec['t']:.1f} s ({dec['after_on_rail_s']:.1f} s after PTO on)"
            if dec
            else "undecided"
        )
        tacho = "used" if c.tacho["used"] else str(c.tacho["note"])
        on = "; ".join(f"{p['time_on']} – {p['time_off']} (t {p['t_on']:.0f}–{p['t_off']:.0f} s)" for p in j["on_rail"])
        parts += [
            f"<h2>{html.escape(c.run_id)}</h2>",
            "<table>"
            f"<tr><th>run</th><td><code>{html.escape(c.run)}</code></td></tr>"
            f"<tr><th>possessions</th><td>{html.escape(', '.join(c.possessions) or 'none')}</td></tr>"
            f"<tr><th>on rail</th><td>{html.escape(on or 'never')}</td></tr>"
            f"<tr><th>track decision</th><td>{html.escape(dec_txt)}</td></tr>"
            f"<tr><th>tacho</th><td>{html.escape(tacho)}</td></tr></table>",
            "<h3>Alarms</h3>",
            _rows(j["alarms"], "alarm"),
            "<h3>Notices</h3>",
            _rows(j["notices"], "note"),
        ]
        png = base64.b64encode(timeline_png(c)).decode()
        alt = f"Timeline of run {c.run_id}"
        parts.append(
            f"<figure><img alt='{html.escape(alt)}' src='data:image/png;base64,{png}'>"
            f"<figcaption>{html.escape(alt)}: km against time, section band, on-rail periods, "
            "km ± uncertainty, fixes, decision, alarms (red) and notices (orange).</figcaption></figure>"
        )
    parts.append("</body></html>")
    return "\n".join(parts)
