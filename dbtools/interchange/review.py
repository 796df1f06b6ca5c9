"""``db review OLD NEW``: one self-contained page for the reviewer of a DB change (page kit).

Sections: a verdict (errors in NEW, and whether anything changed), the validation of NEW
(every finding), the ``db diff`` summary lines and the row counts per table, an interactive
map of NEW's network and of what changed (:mod:`~dbtools.interchange.leaflet_map`: Leaflet
inlined, works offline; tiles only with ``tiles``), and the changed rows per table (capped
at :data:`MAX_ROWS` each; ``db diff --format json`` has them all).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from dbtools import pagekit as pk
from dbtools.diff import diff_networks, load_network
from dbtools.gis.geometry import Projector
from dbtools.interchange.leaflet_map import OSM_ATTRIBUTION, map_payload, render_map
from dbtools.interchange.mapchanges import map_data
from dbtools.interchange.netmap import map_projector
from dbtools.validate import validate_path
from schemas.enums import Severity
from schemas.findings import Finding, count_by_severity

MAX_ROWS = 200


def _findings_table(findings: list[Finding]) -> str:
    if not findings:
        return pk.paragraph("No finding: every rule passes.", pk.Status.OK)
    rows = [
        [
            pk.Cell(str(f.severity), "warn" if f.severity == Severity.ERROR else "caution"),
            pk.Cell(f.rule, "l"),
            pk.Cell(f.where, "l"),
            pk.Cell(f.message, "l"),
        ]
        for f in findings[:MAX_ROWS]
    ]
    more = (
        pk.paragraph(f"… {len(findings) - MAX_ROWS} more (db validate --format json)", pk.Status.NOTE)
        if len(findings) > MAX_ROWS
        else ""
    )
    return pk.table(["severity", "rule", "where", "message"], rows, cls="text") + more


def _changes_table(rows: list[dict[str, Any]]) -> str:
    out = []
    for r in rows[:MAX_ROWS]:
        keys = ", ".join(f"{k}={v}" for k, v in r["keys"].items())
        changes = "; ".join(
            f"{c}: {a if a is not None else '—'} → {b if b is not None else '—'}" for c, (a, b) in r["changes"].items()
        )
        out.append([pk.Cell(r["change"], "l"), pk.Cell(keys, "l"), pk.Cell(changes, "l")])
    return pk.table(["change", "keys", "values (old → new)"], out, cls="text")


def _map_section(old_net: Any, new_net: Any, d: Any, tiles: str | None, tiles_attribution: str) -> str:
    proj: Projector | None = map_projector(new_net) or map_projector(old_net)
    if proj is None:
        return pk.section("Network map", pk.paragraph("No GIS points: no map.", pk.Status.NOTE))
    changes = map_data(old_net, new_net, d)
    payload = map_payload(new_net, proj, changes, tiles=tiles, tiles_attribution=tiles_attribution)
    caption = (
        f"NEW's network: {len(payload['tracks'])} track(s), {len(payload['switches'])} switch(es), "
        f"{len(payload['connections'])} connection place(s), {len(payload['groups'])} balise group(s); "
        f"{len(payload['changes'])} change(s) marked. Hover for details, click to keep them; "
        f"lines simplified to 0.5 m; " + ("tiles from " + tiles if tiles else "no background tiles (works offline)")
    )
    return pk.section(
        "Network map",
        f"<figure id='map'>{render_map(payload)}<figcaption>{pk.escape(caption)}</figcaption></figure>",
    )


def render_review(
    old: Path, new: Path, *, tiles: str | None = None, tiles_attribution: str = OSM_ATTRIBUTION
) -> tuple[str, list[Finding]]:
    """The review page of OLD → NEW (DB files or source sets) and NEW's findings."""
    old_net, old_sv = load_network(old)
    new_net, new_sv = load_network(new)
    d = diff_networks(old_net, new_net, schema_versions=(old_sv, new_sv))
    findings = validate_path(new)
    counts = count_by_severity(findings)
    ok = counts["error"] == 0
    changed = "content changed" if d.has_changes else "no content change"
    verdict = pk.Verdict(
        f"{'Passed' if ok else 'Failed'}: {pk.counts_text(counts['error'], counts['warning'])} in NEW; {changed}.",
        pk.Status.OK if ok else pk.Status.WARN,
    )
    head = pk.key_value_table(
        [
            ("old", str(old)),
            ("new", str(new)),
            ("old db_version", d.old.get("db_version")),
            ("new db_version", d.new.get("db_version")),
            ("old content_hash", d.old.get("content_hash")),
            ("new content_hash", d.new.get("content_hash")),
        ],
        code=("old content_hash", "new content_hash"),
    )
    counts_frame = pd.DataFrame([{"table": n, **t.counts} for n, t in d.tables.items()])
    parts = [
        head,
        pk.section("Validation of NEW", _findings_table(findings)),
        pk.section(
            "What changed",
            "<ul id='summary'>" + "".join(f"<li>{pk.escape(s)}</li>" for s in d.summary) + "</ul>",
            pk.frame_table(counts_frame),
        ),
        _map_section(old_net, new_net, d, tiles, tiles_attribution),
    ]
    for name, t in d.tables.items():
        if t.n_changes:
            parts.append(
                pk.section(
                    f"{name}: {t.counts['added']} added, {t.counts['removed']} removed, {t.counts['changed']} changed",
                    _changes_table(t.rows()),
                    level=3,
                )
            )
    parts.append(pk.paragraph(pk.generated(), pk.Status.NOTE))
    page = pk.page(
        f"DB review {d.old.get('db_version', old)} → {d.new.get('db_version', new)}",
        *parts,
        description="trainpos db review: validation, diff and map of a DB change",
        verdict=verdict,
    )
    return page, findings


def write_review(
    old: Path,
    new: Path,
    out: Path,
    *,
    force: bool = False,
    tiles: str | None = None,
    tiles_attribution: str = OSM_ATTRIBUTION,
) -> list[Finding]:
    """Write the page atomically (refused when ``out`` exists without ``force``, before any
    work); returns NEW's findings. ``tiles``: an XYZ tile URL template for the map's
    background (none by default: the page then loads nothing from the network)."""
    from dbtools.atomic import atomic_file, check_target

    inputs = [Path(old), Path(new)]
    check_target(Path(out), force=force, kind="file", inputs=inputs)  # before the work
    text, findings = render_review(old, new, tiles=tiles, tiles_attribution=tiles_attribution)
    with atomic_file(Path(out), force=force, inputs=inputs) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return findings
