"""Writing railML 3.2 elements with lxml: the namespace, attribute values (floats in Python's
shortest round-trip form, NaN/None left out, ``tpos_`` names in this suite's extension
namespace :data:`~dbtools.interchange.xmltree.TPOS_NS`) and our register's designators."""

from __future__ import annotations

from typing import Any

import numpy as np

from dbtools.interchange.railml_ids import REGISTER
from dbtools.interchange.xmltree import TPOS_NS

NS = "https://www.railml.org/schemas/3.2"
DC_NS = "http://purl.org/dc/elements/1.1/"
XSI_NS = "http://www.w3.org/2001/XMLSchema-instance"


def fmt(x: Any) -> str:
    return repr(float(x))


def tpos_name(name: str) -> str:
    return f"{{{TPOS_NS}}}{name}"


def sub(parent: Any, tag: str, ns: str = NS, /, **attrs: Any) -> Any:
    from lxml import etree

    el = etree.SubElement(parent, f"{{{ns}}}{tag}")
    for k, v in attrs.items():
        if v is not None and not (isinstance(v, float) and np.isnan(v)):
            el.set(k if not k.startswith("tpos_") else tpos_name(k[5:]), v if isinstance(v, str) else fmt(v))
    return el


def designate(el: Any, entry: object) -> None:
    """``<designator register="_trainpos" entry="DB id"/>`` after the element's names (railML 3
    puts ``designator`` after ``name`` and before the locations)."""
    from lxml import etree

    d = etree.Element(f"{{{NS}}}designator", register=REGISTER, entry=str(entry))
    names = [i for i, c in enumerate(el) if c.tag == f"{{{NS}}}name"]
    el.insert(names[-1] + 1 if names else 0, d)
