"""balise_groups: moving a position past a track end along the topology (hand-computed), and
the grouping rule for balises named by numbers."""

from __future__ import annotations

import pytest

from dbtools.interchange.balise_groups import _follow, _numbered_together, _plain_exits
from dbtools.interchange.model import RailmlDoc, RLink, RTrack


def _doc() -> RailmlDoc:
    """A (100 m) end → B (200 m) end; B begin → C (50 m) begin; C end → D (80 m) begin through a switch."""
    doc = RailmlDoc(file="f", version="2.4")
    for name, length in (("A", 100.0), ("B", 200.0), ("C", 50.0), ("D", 80.0)):
        doc.tracks[name] = RTrack(name, None, length=length)
    doc.links = [
        RLink("A", "end", "B", "end"),
        RLink("B", "begin", "C", "begin"),
        RLink("C", "end", "D", "begin", switch_id="W"),
    ]
    return doc


@pytest.mark.parametrize(
    ("tid", "pos", "expected"),
    [
        ("A", 40.0, ("A", 40.0)),  # on its track
        ("A", 100.4, ("A", 100.4)),  # within the 0.5 m tolerance
        ("A", 130.0, ("B", 170.0)),  # 30 m past A's end = 30 m before B's end
        ("B", -20.0, ("C", 20.0)),  # 20 m before B's begin = 20 m into C from its begin
        ("A", 310.0, ("C", 10.0)),  # past A (10 … 210 m into B, reversed) and 10 m into C
        ("C", 60.0, None),  # past C's end only through a switch: not followed
        ("A", -5.0, None),  # A's begin is open
    ],
)
def test_follow_past_track_ends(tid: str, pos: float, expected: tuple[str, float] | None) -> None:
    doc = _doc()
    assert _follow(doc, _plain_exits(doc), tid, pos) == expected


def test_numbered_together() -> None:
    assert _numbered_together("55025", "55027") and _numbered_together("18770", "18772")
    assert not _numbered_together("55001", "55012")
    assert _numbered_together("B1", "55012") and _numbered_together(None, "1")  # no constraint
