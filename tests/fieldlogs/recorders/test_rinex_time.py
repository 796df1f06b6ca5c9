"""Epoch fields and week numbers of RINEX files (issue 32 item 10), by hand.

Epoch seconds: 0 ≤ s < 61, 60 only as an inserted leap second at 23:59:60 UTC at the end
of a day that ends with one (RINEX 3.05 §6.3; IERS Bulletin C): any other 60 is refused with
its line, never carried into the next minute. Week numbers: a 10-bit broadcast week (mod 1024,
IS-GPS-200 §20.3.3.3.1.1) is resolved against the record's calendar epoch and stated.
"""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fieldlogs.quality.file_findings import FileFindings
from fieldlogs.quality.gnss import check_gnss_nav
from fieldlogs.recorders.common import Decoded
from fieldlogs.recorders.navweeks import nav_onto_observations
from fieldlogs.recorders.rinex import read_rinex
from fieldlogs.recorders.rinex_nav import write_rinex_nav
from fieldlogs.recorders.rinex_obs import write_rinex_obs
from schemas.errors import InputError
from tests.fieldlogs.recorders.conftest import nav_row, obs_frame


def _obs3(tmp_path: Path, epoch: str) -> tuple[Path, int]:
    """A RINEX 3 file whose first epoch record is replaced by ``epoch`` (its 1-based line)."""
    p = tmp_path / "rx.obs"
    write_rinex_obs(obs_frame(2), p)
    lines = p.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith(">"))
    lines[i] = epoch + lines[i][len(epoch) :]
    p.write_text("\n".join(lines) + "\n")
    return p, i + 1


def test_second_60_of_an_ordinary_minute_is_refused_with_its_line(tmp_path: Path) -> None:
    """Before: ``01 00 60.0000000`` became 01:01:00 — the epoch moved without a word."""
    p, row = _obs3(tmp_path, "> 2026 12 01 10 00 60.0000000")
    with pytest.raises(InputError, match=r"second 60\.0000000 is a leap second") as exc:
        read_rinex(p)
    assert (exc.value.path, exc.value.row) == (str(p), row)


@pytest.mark.parametrize(
    ("epoch", "field"),
    [
        ("> 2026 12 01 10 60 00.0000000", "minute 60"),
        ("> 2026 12 01 24 00 00.0000000", "hour 24"),
        ("> 2026 02 30 10 00 00.0000000", "day 30 of a 28-day month"),
        ("> 2026 12 01 10 00 61.0000000", r"second 61\.0000000"),
    ],
)
def test_fields_out_of_range_are_named(tmp_path: Path, epoch: str, field: str) -> None:
    p, row = _obs3(tmp_path, epoch)
    with pytest.raises(InputError, match=f"out of range: {field}") as exc:
        read_rinex(p)
    assert exc.value.row == row


def _time_system(text: str, system: str) -> str:
    out = []
    for ln in text.splitlines():
        if ln[60:].strip() == "TIME OF FIRST OBS":
            ln = ln[:48] + f"{system:<12}" + ln[60:]
        out.append(ln)
    return "\n".join(out) + "\n"


def test_a_real_leap_second_on_a_utc_file_is_placed_exactly(tmp_path: Path) -> None:
    """2016-12-31 23:59:60.5 UTC is 1 s before 2017-01-01 00:00:00.5 UTC; GPS − UTC was 17 s
    during it and 18 s after. Counting 23:59:60.5 as 86 400.5 s of its day (the midnight + 0.5)
    GPS = midnight + 0.5 + 17; 00:00:00.5 is midnight + 0.5 + 18 — one second later, by hand."""
    p = tmp_path / "rx.obs"
    write_rinex_obs(obs_frame(2), p)
    text = _time_system(p.read_text(), "UTC")
    assert "UTC" in next(ln for ln in text.splitlines() if "TIME OF FIRST OBS" in ln)
    eps = [i for i, ln in enumerate(text.splitlines()) if ln.startswith(">")]
    lines = text.splitlines()
    lines[eps[0]] = "> 2016 12 31 23 59 60.5000000" + lines[eps[0]][29:]
    lines[eps[1]] = "> 2017 01 01 00 00 00.5000000" + lines[eps[1]][29:]
    p.write_text("\n".join(lines) + "\n")
    times = np.unique(read_rinex(p).frames["gnss_obs"]["gnss_time_s"])
    midnight = (datetime(2017, 1, 1) - datetime(1980, 1, 6)).days * 86_400.0
    assert times.tolist() == [midnight + 0.5 + 17.0, midnight + 0.5 + 18.0]
    assert np.diff(times).tolist() == [1.0]  # one second apart, as in reality


def test_second_60_on_gps_time_is_refused_even_at_a_leap_second(tmp_path: Path) -> None:
    """GPS time has no leap seconds: 23:59:60 on a GPS-time file is not one."""
    p, row = _obs3(tmp_path, "> 2016 12 31 23 59 60.0000000")
    with pytest.raises(InputError, match="on GPS time is not one") as exc:
        read_rinex(p)
    assert exc.value.row == row


def test_rinex_211_second_60_is_refused(data: Path, tmp_path: Path) -> None:
    p = tmp_path / "rx.obs"
    text = (data / "sample_v211.obs").read_text()
    assert " 26 12  1  0  0  0.0" in text
    p.write_text(text.replace(" 26 12  1  0  0  0.0000000", " 26 12  1  0  0 60.0000000", 1))
    with pytest.raises(InputError, match=r"second 60\.0000000 is a leap second") as exc:
        read_rinex(p)
    assert exc.value.row == 8


def test_navigation_record_with_second_60_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "nav.rnx"
    write_rinex_nav(pd.DataFrame([nav_row("G07")]), p)
    lines = p.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("G07"))
    lines[i] = lines[i][:21] + "60" + lines[i][23:]
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"second 60\.0000000 is a leap second") as exc:
        read_rinex(p)
    assert exc.value.row == i + 1


def test_a_10_bit_week_is_resolved_against_the_record_epoch_and_stated(tmp_path: Path) -> None:
    """2026-12-01 lies in GPS week 2447 (17 131 days since 1980-01-06 → 2447·7 + 2); its
    10-bit broadcast week is 2447 − 2·1024 = 399. Written as 399, read back as 2447."""
    row = nav_row("G07")
    assert row["week"] == 2447.0
    p = tmp_path / "nav.rnx"
    write_rinex_nav(pd.DataFrame([{**row, "week": 399.0}]), p)
    assert " 3.99" in p.read_text().replace("D+02", "").replace("E+02", "")  # the file holds week 399
    dec = read_rinex(p)
    assert dec.frames["gnss_nav"]["week"].tolist() == [2447.0]
    assert len(dec.notes) == 1
    assert "+2048 weeks" in dec.notes[0] and "modulo 1024" in dec.notes[0] and "1 record(s)" in dec.notes[0]


def test_a_continuous_week_is_left_alone(tmp_path: Path) -> None:
    p = tmp_path / "nav.rnx"
    write_rinex_nav(pd.DataFrame([nav_row("G07")]), p)
    dec = read_rinex(p)
    assert dec.frames["gnss_nav"]["week"].tolist() == [2447.0]
    assert dec.notes == []


def _decoded(nav: pd.DataFrame, t_obs: float) -> list[Decoded]:
    obs = Decoded("rx.obs", "rinex", frames={"gnss_obs": pd.DataFrame({"gnss_time_s": [t_obs, t_obs + 60.0]})})
    return [obs, Decoded("rx.nav", "rinex", frames={"gnss_nav": nav})]


def test_a_file_dated_a_rollover_early_is_moved_onto_the_observations() -> None:
    """A receiver with the rollover bug dates its navigation file 1024 weeks (7168 days) early:
    toc and week both; the observations are right. Moved by exactly 1024·604800 s, and said."""
    row = nav_row("G07")
    early = pd.DataFrame([{**row, "toc_gps_s": float(row["toc_gps_s"]) - 1024 * 604_800.0, "week": 2447.0 - 1024}])
    dec = _decoded(early, float(row["toc_gps_s"]) + 600.0)
    assert nav_onto_observations(dec) == []
    nav = dec[1].frames["gnss_nav"].iloc[0]
    assert (nav["toc_gps_s"], nav["week"]) == (row["toc_gps_s"], 2447.0)
    assert len(dec[1].notes) == 1 and "-1024 weeks" in dec[1].notes[0]


def test_navigation_records_of_another_day_are_named() -> None:
    row = nav_row("G07")
    dec = _decoded(pd.DataFrame([row]), float(row["toc_gps_s"]) + 30 * 86_400.0)
    found = nav_onto_observations(dec)
    assert [f.rule for f in found] == ["import.nav_epochs"] and "-30 days" in found[0].message
    assert dec[1].frames["gnss_nav"].iloc[0]["toc_gps_s"] == row["toc_gps_s"]  # left as it is


def test_logs_check_names_an_unresolved_10_bit_week() -> None:
    """A gnss_nav stream written before this import fix (or by hand): week 399 while toc is in
    week 2447 → one error naming the week, not a silent 0 % availability."""
    out = FileFindings("gnss_nav", "gnss_nav.parquet", 10)
    frame = pd.DataFrame([{**nav_row("G07"), "week": 399.0}, nav_row("G12")])
    check_gnss_nav(out, frame)
    weeks = [f for f in out.items if f.rule == "log.nav_week"]
    assert len(weeks) == 1 and weeks[0].row == 2 and weeks[0].column == "week" and "-2048 weeks" in weeks[0].message
