"""Two GEOs logged (MSAS PRN 129 and 137): one GEO's complete set per time, kept while usable,
switched when it times out or sends MT 0 — hand-built messages through the encoder."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fieldlogs.gnss.report import sbas_summary
from fieldlogs.gnss.sbas import SbasCorrections
from fieldlogs.gnss.sbas.geo_select import NO_GEO
from fieldlogs.simulate.gnss import sbas_encode as enc

T0 = 1_400_000_000.0
LAG = 1.125  # reception 1.125 s after the time of applicability


def _geo(prn: int, prc_m: float, start: float, stop: float, mt0_at: float | None = None) -> pd.DataFrame:
    """A GEO sending from T0 + start to T0 + stop: MT 1, 7, 25 at the start and every 60 s, MT 2
    (G01's correction ``prc_m``, constant: no range rate) every 6 s, MT 0 at ``mt0_at``."""
    lt = enc.LongTerm(1, 7, 0.0, 0.0, 0.0, 0.0)
    msgs: list[tuple[float, bytes]] = []
    iodf = 0
    for k, s in enumerate(np.arange(start, stop + 0.5, 1.0)):
        t = T0 + float(s)
        if mt0_at is not None and s == mt0_at:
            msgs.append((t, enc.mt0()))
            continue
        phase = k % 6
        if phase == 0:
            iodf = (iodf + 1) % 3
            msgs.append((t, enc.mt_fast(2, iodf, 1, [prc_m], [0])))
        elif k % 60 in (1, 2, 3) or (mt0_at is not None and 1 <= s - mt0_at <= 3):
            kind = (k % 60) if k % 60 in (1, 2, 3) else int(s - mt0_at)  # type: ignore[operator]
            m = {1: enc.mt1([1], 1), 2: enc.mt7(0, 1, [0]), 3: enc.mt25((False, [lt]), (False, []), 1)}[kind]
            msgs.append((t, m))
    return pd.DataFrame(
        {
            "t": [t - T0 for t, _ in msgs],
            "gnss_time_s": [t + LAG for t, _ in msgs],
            "prn": prn,
            "message_hex": [m.hex().upper() for _, m in msgs],
        }
    )


def _rows(sb: SbasCorrections, t: np.ndarray) -> np.ndarray:
    out = sb.rows(np.full(t.size, "G01"), t, np.full(t.size, 7.0))
    return np.where(out.present, out.prc_m, np.nan)


def test_one_geo_kept_while_usable_then_switch_on_time_out_and_on_mt0() -> None:
    a = _geo(137, 1.0, 0, 60)  # stops after 60 s …
    a2 = _geo(137, 1.0, 80, 200)  # … and is back at 80 s
    b = _geo(129, 2.0, 3, 200, mt0_at=130)  # from 3 s; "do not use" at 130 s
    frame = pd.concat([a, a2, b], ignore_index=True).sort_values("gnss_time_s", kind="stable")
    sb = SbasCorrections.from_stream(frame)
    assert sorted(sb.geos) == [129, 137]
    t = T0 + np.array([10.0, 60.0, 78.0, 80.0, 100.0, 129.0, 132.0, 150.0])
    geo = sb.active(t)
    # 137 first (usable first); its last fast correction at 60 + 1.125 s times out at 79.125 s
    # → 129; 137 back at 80 s but 129 is kept; 129's MT 0 (received 131.125 s) → 137
    assert geo.tolist() == [137, 137, 137, 129, 129, 129, 137, 137]
    prc = _rows(sb, t)
    np.testing.assert_allclose(prc, [1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 1.0, 1.0])  # never a mixture
    assert sb.used == {137: 5, 129: 3} and sb.counts["corrected"] == 8
    assert sb.timeline.switches() == 2
    s = sbas_summary(sb)
    assert s["prn"] == 137 and s["switches"] == 2 and s["geos"]["129"]["rows"] == 3
    # the switch instants exactly: 137 timed out just after 79.125 s, 129's MT 0 at 131.125 s
    out_at = T0 + 60.0 + LAG + 18.0
    edge = np.array([out_at, np.nextafter(out_at, np.inf), T0 + 130.0 + LAG - 1e-6, T0 + 130.0 + LAG])
    assert sb.active(edge).tolist() == [137, 129, 129, 137]


def test_each_row_equals_the_single_geo_corrections_of_its_geo() -> None:
    a, b = _geo(137, 1.0, 0, 60), _geo(129, 2.0, 3, 200)
    both = SbasCorrections.from_stream(pd.concat([a, b], ignore_index=True))
    t = T0 + np.arange(5.0, 200.0, 1.0)
    geo = both.active(t)
    got = _rows(both, t)
    for prn, frame in ((137, a), (129, b)):
        alone = _rows(SbasCorrections.from_stream(frame), t)
        np.testing.assert_array_equal(got[geo == prn], alone[geo == prn])
    assert set(geo.tolist()) == {137, 129}


def test_no_usable_geo_leaves_rows_uncorrected() -> None:
    sb = SbasCorrections.from_stream(_geo(137, 1.0, 0, 30))
    t = T0 + np.array([-5.0, 20.0, 31.0 + LAG + 18.0 + 1.0])
    assert sb.active(t).tolist() == [NO_GEO, 137, NO_GEO]
    prc = _rows(sb, t)
    assert np.isnan(prc[0]) and prc[1] == pytest.approx(1.0) and np.isnan(prc[2])
    assert sb.counts["no_usable_geo"] == 2


def test_a_pinned_prn_uses_that_geo_only() -> None:
    frame = pd.concat([_geo(137, 1.0, 0, 60), _geo(129, 2.0, 3, 200)], ignore_index=True)
    sb = SbasCorrections.from_stream(frame, prn=129)
    assert list(sb.geos) == [129]
    np.testing.assert_allclose(_rows(sb, T0 + np.array([20.0, 100.0])), [2.0, 2.0])


def test_qzss_slots_of_the_mask_are_corrected_and_galileo_never() -> None:
    from fieldlogs.gnss.sbas_tables import mask_slot_sat

    assert mask_slot_sat(np.array([1, 37, 38, 61, 62, 120, 158, 183, 192, 193, 202, 203])) == [
        "G01", "G37", "R01", "R24", "", "S20", "S58", "", "", "J01", "J10", ""]  # fmt: skip
    lt = [enc.LongTerm(1, 7, 0.5, 0.0, 0.0, 0.0), enc.LongTerm(2, 40, -1.0, 0.0, 0.0, 0.0)]
    msgs = [
        (T0, enc.mt1([3, 193], 1)),  # slot 1 = G03, slot 2 = J01 (QZSS PRN 193)
        (T0 + 1, enc.mt7(0, 1, [0, 0])),
        (T0 + 2, enc.mt25((False, lt), (False, []), 1)),
        (T0 + 3, enc.mt_fast(2, 1, 1, [1.5, -2.25], [0, 1])),
    ]
    frame = pd.DataFrame(
        {"t": [t - T0 for t, _ in msgs], "gnss_time_s": [t + LAG for t, _ in msgs], "prn": 137,
         "message_hex": [m.hex().upper() for _, m in msgs]}
    )  # fmt: skip
    sb = SbasCorrections.from_stream(frame)
    out = sb.rows(np.array(["G03", "J01", "E05", "J02"]), np.full(4, T0 + 6.0), np.array([7.0, 40.0, 40.0, 40.0]))
    assert out.present.tolist() == [True, True, False, False]
    assert out.prc_m[1] == -2.25 and out.dpos_m[1].tolist() == [-1.0, 0.0, 0.0]
    assert out.sigma_m[1] == pytest.approx(np.sqrt(0.0924) + 8.0)  # UDREI 1, no MT 10


def test_the_receiver_clock_is_not_coasted_across_a_geo_switch() -> None:
    from types import SimpleNamespace
    from typing import cast

    from fieldlogs.gnss.observables import Epochs
    from fieldlogs.gnss.position import clock_segments

    frame = pd.concat([_geo(137, 1.0, 0, 60), _geo(137, 1.0, 80, 200), _geo(129, 2.0, 3, 200, mt0_at=130)])
    sb = SbasCorrections.from_stream(frame)
    ep = cast(Epochs, SimpleNamespace(receiver=np.array(["rx1", "rx2"] * 3), t=T0 + np.repeat([10.0, 100.0, 150.0], 2)))
    seg = clock_segments(ep, sb)  # 137, then 129 (from 79 s), then 137 (from 131 s): three stretches
    assert seg[0] != seg[1] and seg[0].startswith("rx1") and len({seg[0], seg[2], seg[4]}) == 3
    assert clock_segments(ep, None).tolist() == ["rx1", "rx2"] * 3
