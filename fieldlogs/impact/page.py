"""The self-contained HTML page of ``trainpos db impact`` (:mod:`dbtools.pagekit`).

A verdict, the two versions, the per-route table (old → new with the change), one figure of
the balise-correction % per run (old vs new), the runs whose figures changed with their
changed corrections, and the runs a version could not replay.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from dbtools import pagekit as kit
from fieldlogs.impact.report import FIGURES, ImpactReport

#: Changed corrections listed per run at most (the JSON has all of them).
MAX_LISTED = 30


def _compare(old: Any, new: Any, change: Any) -> str:
    if old is None and new is None:
        return "—"
    text = f"{kit.number_text(old) if old is not None else '—'} → {kit.number_text(new) if new is not None else '—'}"
    if change not in (None, 0, 0.0):
        text += f" ({'+' if change > 0 else ''}{kit.number_text(change)})"
    return text


def figure_frame(rows: list[dict[str, Any]], keys: tuple[str, ...]) -> pd.DataFrame:
    """Rows with ``old``/``new``/``delta`` figures as one text column per figure."""
    out = []
    for r in rows:
        line = {k: r.get(k) for k in keys}
        for k, label in FIGURES.items():
            line[label] = _compare(r["old"].get(k), r["new"].get(k), r["delta"].get(k))
        out.append(line)
    return pd.DataFrame(out)


def _cell(column: str, v: Any) -> kit.Cell:
    if isinstance(v, str) and "→" in v:
        return kit.Cell(v, "l" if "(" not in v else "l warn")
    return kit.default_cell(column, v)


def pct_figure(runs: list[dict[str, Any]]) -> bytes:
    """Mean balise-correction % per run, old vs new."""
    names = [str(r.get("run_id") or r["run"]) for r in runs]
    old = [r["old"].get("balise_mean_pct") for r in runs]
    new = [r["new"].get("balise_mean_pct") for r in runs]
    x = np.arange(len(runs))
    fig, ax = kit.pyplot().subplots(figsize=(max(6.0, 0.5 * len(runs) + 2), 3.2))
    ax.bar(x - 0.2, [np.nan if v is None else v for v in old], 0.4, label="old", color="0.6")
    ax.bar(x + 0.2, [np.nan if v is None else v for v in new], 0.4, label="new", color="tab:blue")
    ax.set_xticks(x, names, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("mean balise correction [%]")
    ax.set_xlabel("run [id]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return kit.png(fig)


def refusal_frame(routes: list[dict[str, Any]]) -> pd.DataFrame:
    """Feature refusals by failed diagnostic per route, old and new."""
    rows = []
    for r in routes:
        diags = sorted(set(r["refusals"]["old"]) | set(r["refusals"]["new"]))
        for diag in diags:
            rows.append(
                {
                    "track_id": r["track_id"],
                    "line_code": r["line_code"],
                    "track": r["track"],
                    "direction": r["direction"],
                    "diagnostic": diag,
                    "old": r["refusals"]["old"].get(diag, 0),
                    "new": r["refusals"]["new"].get(diag, 0),
                }
            )
    return pd.DataFrame(rows)


def _verdict(d: dict[str, Any]) -> kit.Verdict:
    t = d["totals"]
    if t["runs_failed"]["new"] > t["runs_failed"]["old"]:
        return kit.Verdict(
            f"Failed: the new version cannot replay {t['runs_failed']['new']} run(s) (old: {t['runs_failed']['old']}).",
            kit.Status.WARN,
        )
    if d["same_content"]:
        return kit.Verdict("No change: both files have the same content.", kit.Status.OK)
    if not t["runs_changed"]:
        return kit.Verdict(f"No change: none of the {t['runs']} run(s) changes.", kit.Status.OK)
    return kit.Verdict(
        f"Changes: {t['runs_changed']} of {t['runs']} run(s) change; {t['corrections_changed']} correction(s) differ.",
        kit.Status.CAUTION,
    )


def _changed_runs(runs: list[dict[str, Any]]) -> list[str]:
    parts = []
    for r in runs:
        ch = r["changed_corrections"]
        if not ch:
            continue
        frame = pd.DataFrame(ch[:MAX_LISTED])
        more = f" ({len(ch) - MAX_LISTED} more in the JSON)" if len(ch) > MAX_LISTED else ""
        parts.append(kit.section(f"{r.get('run_id') or r['run']}{more}", kit.frame_table(frame), level=3))
    return parts


def render_html(report: ImpactReport) -> str:
    """The whole impact report as one HTML string."""
    d = report.to_dict()
    sides = [
        ("old", f"{d['old']['path']} (version {d['old']['db_version']}, content {d['old']['content_hash'][:12]})"),
        ("new", f"{d['new']['path']} (version {d['new']['db_version']}, content {d['new']['content_hash'][:12]})"),
        ("runs", d["totals"]["runs"]),
        ("possession plan", d["plan"] or "—"),
    ]
    parts = [
        kit.paragraph(f"{kit.generated()}."),
        kit.key_value_table(sides),
        kit.section(
            "Per route",
            kit.frame_table(figure_frame(d["routes"], ("track_id", "line_code", "track", "direction", "runs")), _cell),
        ),
    ]
    refusals = refusal_frame(d["routes"])
    if len(refusals):
        parts.append(kit.section("Feature refusals by diagnostic", kit.frame_table(refusals)))
    if d["runs"]:
        parts.append(kit.section("Balise-correction % per run", kit.figure(pct_figure(d["runs"]), "old vs new")))
        parts.append(
            kit.section(
                "Per run",
                kit.frame_table(
                    figure_frame(d["runs"], ("run_id", "vehicle_id", "track_id", "line_code", "track")), _cell
                ),
            )
        )
    changed = _changed_runs(d["runs"])
    if changed:
        parts.append(kit.section("Corrections that change", *changed))
    failed = [r for r in d["runs"] if r["errors"]["old"] or r["errors"]["new"]]
    if failed:
        frame = pd.DataFrame([{"run": r["run"], "old": r["errors"]["old"], "new": r["errors"]["new"]} for r in failed])
        parts.append(kit.section("Runs a version cannot replay", kit.frame_table(frame), status=kit.Status.WARN))
    return kit.page("trainpos db impact", *parts, heading_text="Impact of a new DB version", verdict=_verdict(d))
