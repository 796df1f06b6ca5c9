"""``db impact``, the report: per run and per route, what the new DB version changes.

Per run and version the figures of :mod:`fieldlogs.impact.replay`; per run the difference
new − old of every figure and the corrections that changed (matched by type, DB row and
time: the same balise read at the same moment), appeared or disappeared. Per route (track id —
the track claimed on most cycles — with its line and track names, and direction of the old
version's replay) the correction statistics are recomputed over
the route's corrections with :func:`fieldlogs.pipeline.corrections.correction_stats` — the
mean % of a route is the mean over its corrections, not a mean of run means.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from fieldlogs.impact.replay import RunFigures
from fieldlogs.pipeline.corrections import correction_stats
from schemas.enums import EventType

#: Figures compared per run and per route (name → what it is), in report order.
FIGURES = {
    "n_balise": "balise corrections",
    "balise_mean_pct": "mean balise correction %",
    "balise_max_pct": "max balise correction %",
    "n_feature": "feature-point corrections",
    "feature_mean_pct": "mean feature correction %",
    "feature_max_pct": "max feature correction %",
    "n_refused": "feature corrections refused",
    "n_anomalies": "balise anomalies",
    "n_failsafe": "fail-safes",
    "n_alarms": "possession alarms",
    "max_margin_m": "max margin [m]",
}
#: A correction amount that moved less than this is unchanged [m].
CHANGE_TOL_M = 0.01
#: A route: the track claimed on most cycles (the summary's ``track_id``), its display names and
#: the direction; the names are attributes of the id, so grouping by all four is by the id.
ROUTE_KEYS = ("track_id", "line_code", "track", "direction")


def run_figures(f: RunFigures) -> dict[str, Any]:
    """The :data:`FIGURES` of one version's replay of one run (None where undefined or failed)."""
    if not f.ok:
        return dict.fromkeys(FIGURES)
    s = f.summary
    return {
        "n_balise": s["balise"]["n_corrections"],
        "balise_mean_pct": s["balise"]["mean_correction_pct"],
        "balise_max_pct": s["balise"]["max_correction_pct"],
        "n_feature": s["feature"]["n_corrections"],
        "feature_mean_pct": s["feature"]["mean_correction_pct"],
        "feature_max_pct": s["feature"]["max_correction_pct"],
        "n_refused": s.get("n_feature_refused"),
        "n_anomalies": s.get("n_anomalies"),
        "n_failsafe": s.get("n_failsafe"),
        "n_alarms": None if f.alarms is None else sum(f.alarms.values()),
        "max_margin_m": s.get("max_margin_m"),
    }


def delta(old: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """new − old per figure (None where either is undefined)."""
    out: dict[str, Any] = {}
    for k in FIGURES:
        a, b = old.get(k), new.get(k)
        out[k] = None if a is None or b is None else _round(b - a)
    return out


def _round(v: Any) -> Any:
    return round(float(v), 6) if isinstance(v, float) else v


def changed_corrections(old: RunFigures, new: RunFigures) -> list[dict[str, Any]]:
    """Corrections whose amount changed by more than :data:`CHANGE_TOL_M`, or that only
    one version made: ``{"type", "row", "t", "old_m", "new_m", "delta_m", "old_pct", "new_pct"}``."""
    cols = ["type", "row", "t", "correction_m", "correction_pct"]

    def frame(f: RunFigures) -> pd.DataFrame:
        d = pd.DataFrame(f.corrections, columns=[*cols, "km_m"])[cols]
        return d.assign(t=d["t"].astype(float).round(1))

    m = frame(old).merge(frame(new), on=["type", "row", "t"], how="outer", suffixes=("_old", "_new"))
    a = m["correction_m_old"].astype(float)
    b = m["correction_m_new"].astype(float)
    changed = (a.isna() != b.isna()) | ((b - a).abs() > CHANGE_TOL_M)
    out = []
    for r in m[changed.to_numpy()].itertuples(index=False):
        old_m, new_m = _opt(r.correction_m_old), _opt(r.correction_m_new)
        out.append(
            {
                "type": r.type,
                "row": r.row,
                "t": float(r.t),  # type: ignore[arg-type]
                "old_m": old_m,
                "new_m": new_m,
                "delta_m": None if old_m is None or new_m is None else round(new_m - old_m, 6),
                "old_pct": _opt(r.correction_pct_old),
                "new_pct": _opt(r.correction_pct_new),
            }
        )
    return out


def _opt(v: Any) -> float | None:
    f = float(v) if v is not None else float("nan")
    return round(f, 6) if np.isfinite(f) else None


def _refusals(f: RunFigures) -> dict[str, int]:
    return dict(f.summary.get("feature_refusals") or {}) if f.ok else {}


@dataclass
class RunImpact:
    """One run: its identity and route, both versions' figures, what changed."""

    run: str
    old: RunFigures
    new: RunFigures

    @property
    def ident(self) -> dict[str, Any]:
        s = self.old.summary if self.old.ok else self.new.summary
        return {k: s.get(k) for k in ("run_id", "vehicle_id", "vehicle_kind", *ROUTE_KEYS)}

    def to_dict(self) -> dict[str, Any]:
        o, n = run_figures(self.old), run_figures(self.new)
        return {
            "run": self.run,
            **self.ident,
            "old": o,
            "new": n,
            "delta": delta(o, n),
            "refusals": {"old": _refusals(self.old), "new": _refusals(self.new)},
            "alarms": {"old": self.old.alarms, "new": self.new.alarms},
            "errors": {"old": self.old.error, "new": self.new.error},
            "changed_corrections": changed_corrections(self.old, self.new) if self.old.ok and self.new.ok else [],
        }


def _route_stats(runs: list[RunImpact], side: str) -> pd.DataFrame:
    """Per route: runs replayed, correction statistics over the route's corrections and the
    summed counts of one version (``side`` old or new)."""
    rows, corr = [], []
    for r in runs:
        f: RunFigures = getattr(r, side)
        key = tuple(r.ident.get(k) or "—" for k in ROUTE_KEYS)
        figs = run_figures(f)
        rows.append({**dict(zip(ROUTE_KEYS, key, strict=True)), "ok": int(f.ok), **figs})
        corr += [{**dict(zip(ROUTE_KEYS, key, strict=True)), **c} for c in f.corrections]
    base = pd.DataFrame(rows)
    g = base.groupby(list(ROUTE_KEYS), sort=True)
    out = pd.DataFrame({"runs": g.size(), "replayed": g["ok"].sum()})
    for k in ("n_refused", "n_anomalies", "n_failsafe", "n_alarms"):
        out[k] = g[k].sum(min_count=1)
    out["max_margin_m"] = g["max_margin_m"].max()
    ev = pd.DataFrame(corr, columns=[*ROUTE_KEYS, "type", "correction_pct"])
    for name, types, population in (
        ("balise", [EventType.BALISE_CORRECTION], "balise"),
        ("feature", [EventType.FEATURE_CORRECTION], "all"),
    ):
        sub = ev[ev["type"].isin([str(t) for t in types])]
        st = correction_stats(sub, ROUTE_KEYS, population=population, index=out.index)  # type: ignore[arg-type]
        out[f"n_{name}"] = st["n_corrections"].to_numpy()
        out[f"{name}_mean_pct"] = st["mean_correction_pct"].to_numpy()
        out[f"{name}_max_pct"] = st["max_correction_pct"].to_numpy()
    return out


def _route_refusals(runs: list[RunImpact]) -> dict[tuple[str, ...], dict[str, dict[str, int]]]:
    """Per route, feature refusals by failed diagnostic, summed over its runs, per version."""
    out: dict[tuple[str, ...], dict[str, dict[str, int]]] = {}
    for r in runs:
        key = tuple(str(r.ident.get(k) or "—") for k in ROUTE_KEYS)
        sides = out.setdefault(key, {"old": {}, "new": {}})
        for side in ("old", "new"):
            for diag, n in _refusals(getattr(r, side)).items():
                sides[side][diag] = sides[side].get(diag, 0) + int(n)
    return out


def route_table(runs: list[RunImpact]) -> list[dict[str, Any]]:
    """Per route: ``{track_id, line_code, track, direction, runs, replayed, old: {figures}, new: {…},
    delta: {…}, refusals: {old, new: {diagnostic: count}}}``."""
    if not runs:
        return []
    old, new = _route_stats(runs, "old"), _route_stats(runs, "new")
    refusals = _route_refusals(runs)
    out = []
    for key in old.index:
        o = {k: _plain(old.loc[key, k]) for k in FIGURES}
        n = {k: _plain(new.loc[key, k]) for k in FIGURES}
        out.append(
            {
                **dict(zip(ROUTE_KEYS, key, strict=True)),
                "runs": int(old.loc[key, "runs"]),
                "replayed": {"old": int(old.loc[key, "replayed"]), "new": int(new.loc[key, "replayed"])},
                "old": o,
                "new": n,
                "delta": delta(o, n),
                "refusals": refusals.get(tuple(str(k) for k in key), {"old": {}, "new": {}}),
            }
        )
    return out


def _plain(v: Any) -> Any:
    if v is None or (isinstance(v, float | np.floating) and not np.isfinite(v)):
        return None
    if isinstance(v, np.integer | int):
        return int(v)
    if isinstance(v, np.floating | float):
        f = float(v)
        return int(f) if f.is_integer() and abs(f) < 2**53 else round(f, 6)
    return v


@dataclass
class ImpactReport:
    """What ``trainpos db impact`` shows."""

    old: dict[str, Any]
    """path, db_version, content_hash of the old DB."""
    new: dict[str, Any]
    plan: str | None
    runs: list[RunImpact] = field(default_factory=list)

    @property
    def same_content(self) -> bool:
        return bool(self.old.get("content_hash") == self.new.get("content_hash"))

    def to_dict(self) -> dict[str, Any]:
        runs = [r.to_dict() for r in self.runs]
        changed = [r for r in runs if any(v not in (None, 0) for v in r["delta"].values()) or r["changed_corrections"]]
        return {
            "old": self.old,
            "new": self.new,
            "plan": self.plan,
            "same_content": self.same_content,
            "totals": {
                "runs": len(runs),
                "runs_changed": len(changed),
                "runs_failed": {
                    "old": sum(1 for r in self.runs if not r.old.ok),
                    "new": sum(1 for r in self.runs if not r.new.ok),
                },
                "corrections_changed": sum(len(r["changed_corrections"]) for r in runs),
            },
            "routes": route_table(self.runs),
            "runs": runs,
        }
