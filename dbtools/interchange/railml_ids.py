"""railML ids from DB ids: always an XML NCName, injective, and the DB id kept in a designator.

railML 3 types every ``@id`` as ``xs:ID`` (an NCName: a letter or ``_`` first, then letters,
digits, ``.``, ``-``, ``_``; no ``:``, no space) and requires it unique in the whole document,
across element kinds. DB ids are free text (balise ``0420-01-U-I1`` starts with a digit; a
feature id may hold spaces or Japanese), so the export never writes one as it is:

* :func:`xml_id` ``(kind, *parts)`` = ``kind`` ``_`` ``esc(part1)`` ``_`` ``esc(part2)`` …,
  ``kind`` a fixed ASCII word per element kind (``bal``, ``sl``, ``ne``, ``hc`` …);
* :func:`escape` keeps ``A–Z a–z 0–9 -`` and writes every other character ``c`` as
  ``.HEX.`` (``hex(ord(c))``, upper case): ``_`` → ``.5F.``, space → ``.20.``, ``駅`` →
  ``.99C5.``. Its output never holds ``_``, so the parts split back at ``_`` exactly and each
  part decodes uniquely (:func:`unescape`): the map (kind, parts) → id is injective, and it is
  an NCName since it starts with the kind's letter and uses only ASCII name characters.

ASCII only on purpose: an NCName may hold most non-ASCII letters, but which ones depends on
the XML edition a consumer implements; escaped ids are valid under every edition.

The DB id itself travels in standard railML 3 as ``<designator register="_trainpos"
entry="DB id"/>`` (:data:`REGISTER`), which the importer prefers to ``@id``
(:func:`designator`).
"""

from __future__ import annotations

import re
from typing import Any

#: The designator register of this suite's DB ids (railML ``designator/@register``).
REGISTER = "_trainpos"

_KEEP = re.compile(r"[A-Za-z0-9-]")
_ESCAPED = re.compile(r"\.([0-9A-F]+)\.")
_KIND = re.compile(r"[A-Za-z][A-Za-z0-9]*")


def escape(part: object) -> str:
    """``part`` (as text) with every character outside ``A–Z a–z 0–9 -`` as ``.HEX.``."""
    return "".join(c if _KEEP.fullmatch(c) else f".{ord(c):X}." for c in str(part))


def unescape(text: str) -> str:
    """The inverse of :func:`escape`."""
    return _ESCAPED.sub(lambda m: chr(int(m.group(1), 16)), text)


def xml_id(kind: str, *parts: object) -> str:
    """The railML ``@id`` of the element of ``kind`` named by ``parts`` (module doc)."""
    if not _KIND.fullmatch(kind):
        raise ValueError(f"id kind {kind!r} is not an ASCII word")
    return "_".join([kind, *(escape(p) for p in parts)])


def designator(el: Any) -> str | None:
    """The ``entry`` of the element's ``designator`` of :data:`REGISTER`, or None."""
    for d in el:
        tag = d.tag
        if isinstance(tag, str) and tag.rsplit("}", 1)[-1] == "designator" and d.get("register") == REGISTER:
            entry = d.get("entry")
            return None if entry is None else str(entry)
    return None
