"""Declared time zones and offset-less ISO 8601 stamps (vendor GNSS traces, issue 31)."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from fieldlogs.recorders.timebase import GPS_EPOCH, StampError, stamps_to_gps, time_zone, utc_to_gps


def gps(utc: str) -> float:
    dt = datetime.fromisoformat(utc).replace(tzinfo=UTC)
    return float(utc_to_gps((dt - GPS_EPOCH).total_seconds()))


@pytest.mark.parametrize(
    ("zone", "offset_h"), [("UTC", 0), ("Z", 0), ("+02:00", 2), ("+0530", 5.5), ("-03", -3), ("Europe/Oslo", 2)]
)
def test_zones(zone: str, offset_h: float) -> None:
    tz = time_zone(zone)
    assert datetime(2026, 5, 25, 12, tzinfo=tz).utcoffset() == timedelta(hours=offset_h)


def test_daylight_saving_of_a_named_zone() -> None:
    oslo = time_zone("Europe/Oslo")
    assert datetime(2026, 1, 15, 12, tzinfo=oslo).utcoffset() == timedelta(hours=1)  # CET in winter


@pytest.mark.parametrize("bad", ["+25:00", "+1:2", "Mars/Olympus", ""])
def test_bad_zones(bad: str) -> None:
    with pytest.raises(ValueError):
        time_zone(bad)


def test_mixed_precision_local_stamps() -> None:
    # 13:09:54.400 CEST = 11:09:54.4 UTC; 18 leap seconds since 2017
    g = stamps_to_gps(["2026-05-25 13:09:54.400", "2026-05-25T13:09:55", "2026-05-25 13:09:55.12345678"],
                      time_zone("Europe/Oslo"))  # fmt: skip
    base = gps("2026-05-25T11:09:54")
    assert list(g - base) == pytest.approx([0.4, 1.0, 1.123456], abs=1e-6)
    assert base - (datetime(2026, 5, 25, 11, 9, 54, tzinfo=UTC) - GPS_EPOCH).total_seconds() == 18.0


def test_a_stamp_with_an_offset_keeps_it() -> None:
    g = stamps_to_gps(["2026-05-25T13:09:54+01:00"], time_zone("Europe/Oslo"))
    assert g[0] == pytest.approx(gps("2026-05-25T12:09:54"))


def test_refusals_name_the_row() -> None:
    with pytest.raises(StampError) as e:
        stamps_to_gps(["2026-05-25T13:09:54+02:00", "2026-05-25 13:09:55"], None)
    assert e.value.row == 1 and "no UTC offset" in str(e.value)
    with pytest.raises(StampError) as e:
        stamps_to_gps(["13:09:54 25.05.2026"], time_zone("UTC"))
    assert e.value.row == 0 and "not an ISO 8601" in str(e.value)
