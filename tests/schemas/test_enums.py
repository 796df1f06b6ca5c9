"""Event, alarm and notice types: declared once, each with its meaning (issue 14)."""

from __future__ import annotations

from schemas.enums import ALARM_MEANING, CORRECTION_EVENTS, EVENT_MEANING, AlarmType, EventType, FixSource, NoticeType


def test_every_type_has_a_meaning() -> None:
    assert set(EVENT_MEANING) == set(EventType)
    assert set(ALARM_MEANING) == set(AlarmType) | set(NoticeType)
    assert all(m.strip() for m in (*EVENT_MEANING.values(), *ALARM_MEANING.values()))


def test_values_are_unique_and_plain_text() -> None:
    for enum in (EventType, AlarmType, NoticeType, FixSource):
        values = [str(m) for m in enum]
        assert len(values) == len(set(values))
        assert all(v == v.lower() and " " not in v for v in values)


def test_absolute_sources_are_the_correction_events_sources() -> None:
    assert {s for s in FixSource if s.absolute} == {FixSource.BALISE, FixSource.FEATURE}
    assert CORRECTION_EVENTS == (EventType.BALISE_CORRECTION, EventType.FEATURE_CORRECTION)
