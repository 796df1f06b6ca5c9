"""Safe XML reading for railML, and where an element is (path and line) for findings.

Parsing follows defusedxml's rules with lxml: no external DTD or entity is loaded, no
network access, entities are never expanded, and a document whose DOCTYPE declares an
entity or names an external DTD is refused (billion-laughs and XXE inputs are not read at
all). Namespaces are compared by local name: railML 2.x files in the wild come with the
2013/2016/2018 namespaces, with none (``xmlns=""``), or with prefixes.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

from schemas.enums import Severity
from schemas.errors import InputError
from schemas.findings import Finding

Element = Any  # lxml.etree._Element (lxml ships no stubs)

#: The namespace of this suite's extension attributes in railML (what railML has no
#: attribute for: balise kind, station code, equipment km, feature rows …).
TPOS_NS = "urn:x-trainpos:railml:1"
GML_NS = "http://www.opengis.net/gml/3.2/"


def parse(path: Path) -> Any:
    """The document tree of ``path``; InputError naming the line on malformed XML."""
    from lxml import etree

    from dbtools.inputs import current_limits, regular_file

    path = Path(path)
    if not path.is_file():
        raise InputError("no such file" if not path.exists() else "not a file", path=path)
    path = regular_file(path, "XML file")
    limit = current_limits().max_xml_mb
    size_mb = path.stat().st_size / (1 << 20)
    if size_mb > limit:
        raise InputError(
            f"{size_mb:.0f} MB of XML is more than the {limit:g} MB this tool reads (a railML file is parsed as a "
            "whole tree, about 15× its size in memory): raise [input] max_xml_mb in a --config file if the "
            "machine has the memory",
            path=path,
        )
    parser = etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_pis=True,
    )
    try:
        tree = etree.parse(str(path), parser)
    except etree.XMLSyntaxError as exc:
        line = exc.lineno if isinstance(exc.lineno, int) and exc.lineno > 0 else None
        raise InputError(f"malformed XML: {exc.msg}", path=path, row=line) from exc
    info = tree.docinfo
    dtd = info.internalDTD
    if info.system_url or (dtd is not None and any(True for _ in dtd.iterentities())):
        raise InputError(
            "the DOCTYPE declares entities or an external DTD: refused (entity expansion, external entities)",
            path=path,
            row=1,
        )
    return tree


def local(el: Element) -> str:
    """Local name of an element (or '' for comments and other nodes)."""
    tag = el.tag
    if not isinstance(tag, str):
        return ""
    return tag.rsplit("}", 1)[-1]


def children(el: Element, name: str | None = None) -> list[Element]:
    return [c for c in el if local(c) and (name is None or local(c) == name)]


def child(el: Element, name: str) -> Element | None:
    for c in el:
        if local(c) == name:
            return c
    return None


def descend(el: Element, *names: str) -> list[Element]:
    """Elements at the local-name path ``names`` below ``el`` (every match at every step)."""
    level = [el]
    for name in names:
        level = [c for e in level for c in children(e, name)]
    return level


def iter_named(el: Element, name: str) -> Iterator[Element]:
    for e in el.iter():
        if local(e) == name:
            yield e


def attr(el: Element, name: str) -> str | None:
    """An attribute by local name (any namespace but ours), stripped; None when absent/blank."""
    for key, value in el.attrib.items():
        if key.rsplit("}", 1)[-1] == name and not key.startswith("{" + TPOS_NS):
            text = str(value).strip()
            return text or None
    return None


def tpos(el: Element, name: str) -> str | None:
    """An attribute of this suite's extension namespace (None when absent)."""
    value = el.attrib.get(f"{{{TPOS_NS}}}{name}")
    return None if value is None else str(value)


def path_of(el: Element) -> str:
    """``/railml/infrastructure/tracks/track[3]/…`` (an index only where siblings share the name)."""
    parts: list[str] = []
    node = el
    while node is not None:
        name = local(node)
        parent = node.getparent()
        if parent is not None:
            same = [c for c in parent if local(c) == name]
            if len(same) > 1:
                name = f"{name}[{same.index(node) + 1}]"
        parts.append(name)
        node = parent
    return "/" + "/".join(reversed(parts))


def line_of(el: Element) -> int | None:
    line = getattr(el, "sourceline", None)
    return int(line) if isinstance(line, int) else None


def finding(
    el: Element,
    rule: str,
    message: str,
    *,
    file: str,
    table: str = "railml",
    severity: Severity = Severity.ERROR,
    column: str | None = None,
    value: Any = None,
) -> Finding:
    """A finding on one element: its path and id in ``keys``, its line as ``row``."""
    keys: dict[str, Any] = {"element": path_of(el)}
    ident = attr(el, "id")
    if ident:
        keys["id"] = ident
    return Finding(rule, severity, table, message, keys=keys, value=value, file=file, row=line_of(el), column=column)


def number(el: Element, name: str) -> float | None:
    """A numeric attribute, or None when absent; ValueError when not a number."""
    text = attr(el, name)
    if text is None:
        return None
    value = float(text)
    if value != value or value in (float("inf"), float("-inf")):
        raise ValueError(text)
    return value
