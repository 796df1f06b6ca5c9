"""One kit for the suite's self-contained HTML pages (audit report, GIS verification,
possession check, DB review, DB impact, survey), and its rendering standard (issue 33):

* the page opens with a plain-language verdict under its heading (:func:`page` requires a
  :class:`Verdict`: ``Passed: 0 errors, 2 warnings``);
* a table's columns carry the suite's labels with units (:func:`schemas.labels.display`:
  ``km_m`` → ``km [m]``), a share (0–1) is shown as a percentage;
* a table's header stays in view while its rows scroll (``position: sticky`` in a box of at
  most 80 % of the window's height), a wide table scrolls inside its box, long words wrap:
  the page never scrolls sideways at 1,280 px;
* every plot names each axis's quantity and unit (:func:`png` refuses a figure that does not).

A page is one string: inline CSS, figures as PNG ``data:`` URIs, no script and no external
resource, so the file works offline and can be mailed. Every text that reaches the page goes
through :func:`escape`. Tables come from DataFrames (:func:`frame_table`) or key/value rows
(:func:`key_value_table`) with one number formatting (:func:`number_text`), which a page may
refine per column with a ``cell`` function; cells carry plain text only (a CSS class on the
``<td>`` marks them), so a page stays easy to parse. Figures come from matplotlib
(:func:`pyplot`: headless Agg, imported on first use, never at import time) through
:func:`png` and :func:`figure`.

The kit lives in ``dbtools`` (imports only ``schemas``-level libraries) so that ``dbtools``
pages can use it as well as ``fieldlogs`` and ``cli``.
"""

from __future__ import annotations

import base64
import html
import io
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    from types import ModuleType

    from matplotlib.figure import Figure

CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:2em;color:#222;max-width:1400px}
p,li,dd,dt,figcaption,h1,h2,h3{overflow-wrap:break-word}
td{white-space:nowrap}td.wrap{white-space:normal;min-width:16em}.nw{white-space:nowrap}
table{border-collapse:separate;border-spacing:0;margin:1em 0;font-size:13px}
th,td{border:1px solid #ccc;border-width:0 1px 1px 0;padding:3px 8px;text-align:right;vertical-align:top}
tr>:first-child{border-left-width:1px}tr:first-child>*{border-top-width:1px}
th{background:#f0f0f0}thead th{position:sticky;top:0;z-index:1;box-shadow:0 1px 0 #ccc}
.scroll{overflow:auto;max-height:80vh;max-width:100%;width:fit-content}.scroll>table{margin:0}
p.verdict{font-size:1.15em;padding:.4em .7em;border-left:6px solid #888;background:#f6f6f6}
p.verdict.ok{border-color:#2a7d2a}p.verdict.warn,p.verdict.alarm{border-color:#b00}
p.verdict.caution{border-color:#c77c00}
td.l,th.l,table.kv td,table.kv th,table.text td,table.text th{text-align:left}
.warn,.alarm{color:#b00;font-weight:bold}.ok{color:#070;font-weight:bold}.note{color:#666}
.caution{color:#a60;font-weight:bold}
.badge{display:inline-block;padding:1px 8px;border-radius:9px;font-size:12px;font-weight:bold;color:#fff}
.badge.ok{background:#2a7d2a}.badge.warn,.badge.alarm{background:#b00}.badge.caution{background:#c77c00}
.badge.note{background:#888}
figure{margin:1.5em 0}img{max-width:100%}code{font-size:12px}
dl.legend{font-size:13px}dl.legend dt{font-weight:bold;float:left;clear:left;margin-right:.5em}
dl.legend dd{margin:0 0 .2em 0}
"""


class Status(StrEnum):
    """Tone of a badge, a verdict or a cell (its CSS class)."""

    OK = "ok"
    """Green: checked and fine."""
    CAUTION = "caution"
    """Amber: nothing wrong found, but not everything could be checked."""
    WARN = "warn"
    """Red: a problem."""
    ALARM = "alarm"
    """Red: a safety alarm."""
    NOTE = "note"
    """Grey: information."""


@dataclass(frozen=True)
class Cell:
    """One table cell: its text (escaped by the kit) and an optional CSS class."""

    text: str
    cls: str | None = None


@dataclass(frozen=True)
class Verdict:
    """A page's first words: a plain sentence of what was found (``Passed: 0 errors, 2
    warnings``) and its tone."""

    text: str
    status: Status


def escape(value: object) -> str:
    """Text for HTML (``&``, ``<``, ``>``, quotes escaped)."""
    return html.escape(str(value))


def is_missing(v: object) -> bool:
    """None, NaN, NA or NaT."""
    if v is None or v is pd.NA or v is pd.NaT:
        return True
    return isinstance(v, float | np.floating) and math.isnan(float(v))


def number_text(v: int | float | np.integer[Any] | np.floating[Any]) -> str:
    """The kit's number format: integers with thousands separators; other numbers with
    thousands separators and no decimals from 100 on, else three decimals."""
    if isinstance(v, int | np.integer):
        return f"{int(v):,}"
    x = float(v)
    return f"{x:,.0f}" if abs(x) >= 100 else f"{x:.3f}"


def percent_text(share: float) -> str:
    """A share (0–1) as people read it: ``99.3 %``."""
    return f"{100.0 * share:.1f} %"


def default_cell(column: str, v: object) -> Cell:
    """Empty for a missing value; a share (:func:`schemas.labels.is_share`) by
    :func:`percent_text`, other numbers by :func:`number_text`; everything else as
    left-aligned text."""
    from schemas.labels import is_share

    if is_missing(v):
        return Cell("")
    if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
        return Cell(str(v), "l")
    return Cell(percent_text(float(v)) if is_share(column) else number_text(v))


#: Longest cell kept on one line (a number, a code, a timestamp); a longer text wraps at spaces.
MAX_NOWRAP = 40


def _td(cell: Cell) -> str:
    classes = " ".join(c for c in (cell.cls, "wrap" if len(cell.text) > MAX_NOWRAP else None) if c)
    cls = f' class="{escape(classes)}"' if classes else ""
    return f"<td{cls}>{escape(cell.text)}</td>"


def _th(text: str) -> str:
    """A header cell wrapping at spaces only (``re-adhered`` is not broken at its hyphen)."""
    words = (f"<span class='nw'>{escape(w)}</span>" if "-" in w else escape(w) for w in text.split(" "))
    return f"<th>{' '.join(words)}</th>"


def table(header: Sequence[str], rows: Iterable[Sequence[Cell]], *, cls: str | None = None, scroll: bool = True) -> str:
    """A table of ready cells under a header row (``<thead>``: it stays in view while the rows
    scroll in their box)."""
    head = "".join(_th(c) for c in header)
    body = "".join("<tr>" + "".join(_td(c) for c in row) + "</tr>" for row in rows)
    klass = f" class='{escape(cls)}'" if cls else ""
    out = f"<table{klass}><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
    return f"<div class='scroll'>{out}</div>" if scroll else out


def frame_table(frame: pd.DataFrame, cell: Callable[[str, Any], Cell] = default_cell) -> str:
    """A DataFrame as a table, each value through ``cell(column, value)`` (the machine name),
    each column under its label (:func:`schemas.labels.label`: words and ``[unit]``)."""
    from schemas.labels import label

    columns = [str(c) for c in frame.columns]
    rows = ([cell(c, v) for c, v in zip(columns, rec, strict=True)] for rec in frame.itertuples(index=False, name=None))
    return table([label(c) for c in columns], rows)


def key_value_table(rows: Sequence[tuple[str, object]], *, code: Sequence[str] = ()) -> str:
    """A two-column table of (label, value); labels in ``code`` show their value as code."""
    body = []
    for label, value in rows:
        text = escape("" if value is None else value)
        shown = f"<code>{text}</code>" if label in code else text
        body.append(f"<tr><th>{escape(label)}</th><td>{shown}</td></tr>")
    return f"<div class='scroll'><table class='kv'>{''.join(body)}</table></div>"


def paragraph(text: str, status: Status | None = None) -> str:
    """A paragraph of plain text (escaped)."""
    cls = f" class='{status.value}'" if status else ""
    return f"<p{cls}>{escape(text)}</p>"


def heading(text: str, level: int = 2, status: Status | None = None) -> str:
    cls = f" class='{status.value}'" if status else ""
    return f"<h{level}{cls}>{escape(text)}</h{level}>"


def section(title: str, *parts: str, level: int = 2, status: Status | None = None) -> str:
    """A heading followed by ready HTML parts."""
    return "\n".join([heading(title, level, status), *parts])


def code(text: object) -> str:
    return f"<code>{escape(text)}</code>"


def badge(text: str, status: Status) -> str:
    """A coloured status label (e.g. ``3 alarm(s)``, ``no defect``, ``unverified``)."""
    return f"<span class='badge {status.value}'>{escape(text)}</span>"


def legend(items: Mapping[str, str], title: str | None = None) -> str:
    """Term → meaning, as a definition list (e.g. every alarm type and what it means)."""
    body = "".join(f"<dt>{escape(k)}</dt><dd>{escape(v)}</dd>" for k, v in items.items())
    head = paragraph(title, Status.NOTE) if title else ""
    return f"{head}<dl class='legend'>{body}</dl>"


def generated() -> str:
    """``generated YYYY-MM-DD HH:MM UTC`` (the time the page was made)."""
    return f"generated {datetime.now(UTC):%Y-%m-%d %H:%M} UTC"


def verdict_paragraph(v: Verdict) -> str:
    """The verdict paragraph (``id='verdict'``), the first text under the page's heading."""
    return f"<p id='verdict' class='verdict {v.status.value}'>{escape(v.text)}</p>"


def counts_text(n_errors: int, n_warnings: int) -> str:
    """``0 errors, 1 warning``: counts in words, singular or plural."""
    return f"{n_errors} error{'s' * (n_errors != 1)}, {n_warnings} warning{'s' * (n_warnings != 1)}"


def page(title: str, *parts: str, verdict: Verdict, heading_text: str | None = None, description: str = "") -> str:
    """The whole page: doctype, charset, viewport, title, the kit's CSS, an ``<h1>``, the
    verdict (:func:`verdict_paragraph`) and the parts."""
    meta = f"<meta name='description' content='{escape(description)}'>" if description else ""
    head = (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"{meta}<title>{escape(title)}</title><style>{CSS}</style></head><body>"
    )
    h1 = f"<h1>{escape(heading_text or title)}</h1>"
    return "\n".join([head, h1, verdict_paragraph(verdict), *parts, "</body></html>"])


# ------------------------------------------------------------------------------ figures


def pyplot() -> ModuleType:
    """``matplotlib.pyplot`` on the headless Agg backend, imported on first use."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: An axis label names a quantity, then its unit in brackets: ``t [s]``, ``km [m]``, ``share [%]``.
AXIS_LABEL = re.compile(r"\S.*\[[^\]]+\].*")


class Png(bytes):
    """PNG bytes of a figure, with the labels of its axes (``x: t [s]; y: km [m]``) for the page."""

    axes: str = ""


def _label(axis: Any) -> str:
    return " ".join(axis.get_label_text().split())


def axis_labels(fig: Figure) -> list[str]:
    """Every axis label of ``fig``'s drawn axes (``x: …``, ``y: …``); ValueError naming the
    plot when an axis has no quantity-and-unit label (:data:`AXIS_LABEL`). An axis shared with
    other axes may leave its label to one of them (one x label under a column of plots)."""
    out: list[str] = []
    for ax in fig.get_axes():
        if not ax.get_visible() or not ax.axison:
            continue
        for name, group in (("x", ax.get_shared_x_axes()), ("y", ax.get_shared_y_axes())):
            axis = ax.xaxis if name == "x" else ax.yaxis
            if not axis.get_visible():
                continue
            text = _label(axis)
            siblings = [_label(s.xaxis if name == "x" else s.yaxis) for s in group.get_siblings(ax)]
            if not any(AXIS_LABEL.fullmatch(t) for t in [text, *siblings]):
                title = ax.get_title() or f"axes {fig.get_axes().index(ax) + 1}"
                raise ValueError(f"plot {title!r}: the {name} axis needs a label 'quantity [unit]', has {text!r}")
            if text:
                out.append(f"{name}: {text}")
    return out


def png(fig: Figure, dpi: int = 96) -> Png:
    """A matplotlib figure as PNG bytes (tight bounding box), its axis labels checked
    (:func:`axis_labels`); the figure is closed."""
    try:
        labels = axis_labels(fig)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    finally:
        pyplot().close(fig)
    out = Png(buf.getvalue())
    out.axes = "; ".join(dict.fromkeys(labels))
    return out


def figure(png_bytes: bytes, alt: str, caption: str | None = None) -> str:
    """A PNG embedded as a ``data:`` URI, with ``alt`` text and a caption (``alt`` by default);
    the axes of a :class:`Png` named in ``data-axes`` and at the end of ``alt``."""
    data = base64.b64encode(png_bytes).decode()
    axes = getattr(png_bytes, "axes", "")
    described = f"{alt} ({axes})" if axes else alt
    return (
        f'<figure><img alt="{escape(described)}" data-axes="{escape(axes)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{escape(caption if caption is not None else alt)}</figcaption></figure>"
    )
