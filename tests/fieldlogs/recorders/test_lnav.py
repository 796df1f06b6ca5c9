"""GPS LNAV subframes: encode → decode is exact on the LSB grid; the parity bits react to
every data bit; the week roll-over is resolved."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.recorders import lnav
from tests.fieldlogs.recorders.conftest import nav_row


def _decoded(row: dict[str, object]) -> dict[str, object]:
    subs = [lnav.decode_subframe(w) for w in lnav.encode(row)]
    assert [int(s["sf"]) for s in subs] == [1, 2, 3]
    return lnav.assemble(subs[0], subs[1], subs[2], week_hint=int(row["week"]))  # type: ignore[call-overload]


def test_round_trip_exact() -> None:
    row = nav_row("G07")
    eph = _decoded(row)
    for k, v in eph.items():
        assert v == pytest.approx(row[k], rel=1e-15, abs=1e-25), k


@settings(max_examples=50, deadline=None)
@given(
    st.integers(-(2**21), 2**21 - 1),
    st.integers(0, 2**32 - 1),
    st.integers(-(2**31), 2**31 - 1),
    st.integers(-(2**13), 2**13 - 1),
)
def test_round_trip_over_the_field_ranges(af0: int, ecc: int, m0: int, idot: int) -> None:
    row = nav_row("J02")
    row.update(
        SVclockBias=af0 * 2.0**-31, Eccentricity=ecc * 2.0**-33, M0=m0 * 2.0**-31 * np.pi, IDOT=idot * 2.0**-43 * np.pi
    )
    eph = _decoded(row)
    for k in ("SVclockBias", "Eccentricity", "M0", "IDOT"):
        assert eph[k] == pytest.approx(row[k], rel=1e-15, abs=1e-25), k


def test_parity_changes_with_every_data_bit() -> None:
    for i in range(24):
        assert lnav._parity(1 << i) != 0, i
    assert lnav._parity(0) == 0


def test_week_rollover_resolved_near_the_hint() -> None:
    row = nav_row("G07")
    subs = [lnav.decode_subframe(w) for w in lnav.encode(row)]
    assert subs[0]["wn"] == int(row["week"]) % 1024  # type: ignore[call-overload]
    eph = lnav.assemble(subs[0], subs[1], subs[2], week_hint=int(row["week"]) + 3)  # type: ignore[call-overload]
    assert eph["week"] == row["week"]


def test_iono_utc_page_round_trip() -> None:
    alpha = [18 * 2.0**-30, 15 * 2.0**-27, -1 * 2.0**-24, -2 * 2.0**-24]
    beta = [59 * 2.0**11, 8 * 2.0**14, -2 * 2.0**16, -3 * 2.0**16]
    corr = {"a0_s": -5 * 2.0**-30, "a1_s_per_s": -7 * 2.0**-50, "t_ref_s": 61_440.0, "week": 2447.0}
    words = lnav.encode_iono_utc(alpha, beta, 18, corr, tow6=1000)
    assert lnav.subframe_id(words) == 4
    got = lnav.decode_iono_utc(words, week_hint=2450)
    assert got == {"alpha": alpha, "beta": beta, "leap_seconds": 18, "correction": corr}
    other = lnav.encode(nav_row())[0]
    assert lnav.decode_iono_utc(other, week_hint=2450) is None


def test_preamble_checked() -> None:
    words = lnav.encode(nav_row())[0]
    assert lnav.subframe_id(words) == 1
    assert lnav.subframe_id([0] * 10) == 0
