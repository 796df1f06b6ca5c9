"""What a fix with network candidates claims on each cycle [SPEC §8.3] (vectorised per fix).

Each candidate h of the fix (:mod:`fieldlogs.pipeline.hypotheses`) is dead-reckoned over the
fix's cycles: pos(S) = pos_h + kp·(S − s_ref), margin m_h = the fix's margin + ``extra_m``.
Its interval [pos − m_h, pos + m_h] may reach over an end of its track: the train may then
be on a track beyond that end, at the distance the interval reaches beyond the joint — ahead
(moving toward that end) every navigable exit there; behind (moving away) the track it came
from where it entered at that end (``Hypothesis.came_from``), else any track joined there by a
relation other than ``none``; standing, both. Such a *neighbour* is a
candidate of the cycle too, at

    pos' = entry + dir·out,   out = pos − L (end) or −pos (begin),

entry 0 and dir +1 when it is joined at its begin, its length and −1 at its end. A cycle is
**determined** when its candidates (own and neighbours) lie on one track, **ambiguous**
otherwise: so a joint or a switch within the margin never gives a claim the margin does not
hold. An ambiguous cycle keeps line, track and km when all its candidates share line and
track and agree on km within 0.5 m (a joint inside one line track), else leaves them empty;
its ``candidates`` cell lists every candidate: a JSON list of objects ``track_id``, ``pos_m``,
``km_m`` (null off a line) and ``margin_m``, rounded to mm, one per track (the first entry of
each track present on the cycle) (:func:`claims`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from dbtools.topology import BEGIN, END
from fieldlogs.pipeline.hypotheses import TrackLines
from fieldlogs.pipeline.types import BoolArray, Fix, FloatArray, Hypothesis

#: Candidates agreeing on line, track and km within this give the cycle its km [m].
KM_AGREE_M = 0.5


@dataclass(frozen=True)
class Entry:
    """One candidate over a fix's cycles, present where ``mask``."""

    track_id: str
    pos: FloatArray
    km: FloatArray
    margin: FloatArray
    mask: BoolArray
    kp: int
    line: tuple[str, str]


def _beyond(lines: TrackLines, h: Hypothesis, end: str) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """(ahead, behind): the tracks beyond ``end`` of ``h``'s track the train may reach moving
    toward that end, and those it may have come from (module docstring)."""
    ahead = [(x.track_id, x.end) for x in lines.topo.exits.get((h.track_id, end), [])]
    if h.came_from is not None and _joined_at(lines, h, end, h.came_from):
        return ahead, [h.came_from]
    return ahead, [(o, oe) for o, oe, nav in lines.topo.joined.get((h.track_id, end), []) if nav != "none"]


def _joined_at(lines: TrackLines, h: Hypothesis, end: str, other: tuple[str, str]) -> bool:
    return any((o, oe) == other for o, oe, _ in lines.topo.joined.get((h.track_id, end), []))


def _entry(lines: TrackLines, tid: str, pos: FloatArray, margin: FloatArray, mask: BoolArray, kp: int) -> Entry:
    tl = lines[tid]
    return Entry(tid, pos, tl.km_of_pos(pos), margin, mask, kp, (tl.line_code, tl.track))


def entries(f: Fix, s: FloatArray, motion: FloatArray, base: FloatArray, lines: TrackLines) -> list[Entry]:
    """The fix's candidates over signed travels ``s`` (``motion``: the sign of dS on each cycle,
    0 standing) and their neighbours (module docstring)."""
    out: list[Entry] = []
    every = np.ones(s.shape, dtype=bool)
    for h in f.hyps:
        tl = lines[h.track_id]
        pos, mh = h.pos_m + h.kp * (s - f.s_ref), base + h.extra_m
        out.append(_entry(lines, h.track_id, pos, mh, every, h.kp))
        toward = h.kp * motion
        for end in (BEGIN, END):
            over = pos - mh < 0 if end == BEGIN else pos + mh > tl.length_m
            if not over.any():
                continue
            sgn = -1 if end == BEGIN else 1  # toward this end: pos moving with sign sgn
            ahead, behind = _beyond(lines, h, end)
            beyond = -pos if end == BEGIN else pos - tl.length_m
            for tracks, when in ((ahead, toward * sgn >= 0), (behind, toward * sgn <= 0)):
                for other, oend in tracks:
                    entry, sign = (0.0, 1) if oend == BEGIN else (lines[other].length_m, -1)
                    out.append(_entry(lines, other, entry + sign * beyond, mh, over & when, sign * sgn * h.kp))
    return out


@dataclass
class Claims:
    """Per cycle of a fix: which cycles are ambiguous, and the determined cycles' entry."""

    ambiguous: BoolArray
    same_line: BoolArray
    """Ambiguous cycles whose candidates share line, track and km (km kept)."""
    text: list[str | None]


def claims(ents: list[Entry]) -> Claims:
    """Ambiguity per cycle (more than one track among the present entries) and the text."""
    n = ents[0].pos.size
    ids = sorted({e.track_id for e in ents})
    present = np.zeros((len(ids), n), dtype=bool)
    for e in ents:
        present[ids.index(e.track_id)] |= e.mask
    ambiguous = present.sum(axis=0) > 1
    same = ambiguous.copy()
    first = ents[0]
    for e in ents[1:]:
        agree = (e.line == first.line) & bool(first.line[0]) & (np.abs(e.km - first.km) <= KM_AGREE_M)
        same &= ~e.mask | agree
    text: list[str | None] = [None] * n
    idx = np.flatnonzero(ambiguous)
    listed = np.zeros((len(ents), idx.size), dtype=bool)  # per ambiguous cycle: one per track (the first)
    seen: dict[str, BoolArray] = {}
    for k, e in enumerate(ents):
        before = seen.setdefault(e.track_id, np.zeros(idx.size, dtype=bool))
        listed[k] = e.mask[idx] & ~before
        before |= listed[k]
    cols = [
        dict(zip(np.flatnonzero(listed[k]).tolist(), _items(e, idx[listed[k]]), strict=True))
        for k, e in enumerate(ents)
    ]
    for j, i in enumerate(idx.tolist()):
        text[i] = "[" + ",".join(c[j] for c in cols if j in c) + "]"
    return Claims(ambiguous, same, text)


def _items(e: Entry, idx: npt.NDArray[np.int64]) -> list[str]:
    """The entry's ``candidates`` item on cycles ``idx`` as JSON text, made at once: what the
    compact JSON encoder writes of the object {``track_id``, ``pos_m``, ``km_m``, ``margin_m``}
    of the values rounded to mm (a JSON float is ``repr`` of the float; null for a value that
    is not finite), without a dict and an encoder pass per cycle."""
    head = '{"track_id":' + _COMPACT.encode(e.track_id) + ',"pos_m":'
    return [
        f'{head}{p},"km_m":{k},"margin_m":{m}}}'
        for p, k, m in zip(_texts(e.pos[idx]), _texts(e.km[idx]), _texts(e.margin[idx]), strict=True)
    ]


def _texts(x: FloatArray) -> list[str]:
    """Every element rounded to mm as JSON text (:func:`_text`)."""
    return [_text(v) for v in x.tolist()]


def _text(v: float) -> str:
    """``repr(round(v, 3))`` (the JSON text of v rounded to mm; null when not finite), for |v| < 10¹²
    as ``f"{v:.3f}"`` without its trailing zeros (one left after the point): both are the
    correctly rounded 3-decimal value of v (CPython's ``round`` and ``f`` formatting are the same
    dtoa), and a decimal of ≤ 15 significant digits is the shortest text of its float, which
    ``repr`` writes in fixed notation from 10⁻⁴ to 10¹⁶ — the same text, in half the time."""
    if -1e12 < v < 1e12:
        t = f"{v:.3f}".rstrip("0")
        return t + "0" if t[-1] == "." else t
    return repr(round(v, 3)) if math.isfinite(v) else "null"


#: ``json.dumps(…, separators=(",", ":"))`` made once (dumps builds an encoder per call with these).
_COMPACT = json.JSONEncoder(separators=(",", ":"))


def max_margin(ents: list[Entry]) -> FloatArray:
    """Per cycle, the largest margin among the present entries."""
    stack = np.vstack([np.where(e.mask, e.margin, -np.inf) for e in ents])
    return np.asarray(stack.max(axis=0), dtype=float)
