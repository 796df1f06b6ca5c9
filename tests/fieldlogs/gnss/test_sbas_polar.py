"""IGP bands 9–10 located (DO-229 Table A-14), the grid between 55° and 75° (5° × 5° cells up to
60°, 5° × 10° above), none above 75°, and the pierce point beyond the pole — worked by hand."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fieldlogs.gnss.sbas import SbasCorrections
from fieldlogs.gnss.sbas.grid import H_I_M, R_E_M, pierce_point
from fieldlogs.gnss.sbas_tables import band_igps, igp_key
from fieldlogs.simulate.gnss import sbas_encode as enc

T0 = 1_400_000_000.0


def _igp(band: int, lat: int, lon: int) -> int:
    la, lo = band_igps(band)
    return int(np.flatnonzero((la == lat) & (lo == lon))[0]) + 1


def _grid(bands: dict[int, dict[int, float]]) -> SbasCorrections:
    msgs: list[tuple[float, bytes]] = []
    for k, (band, d) in enumerate(sorted(bands.items())):
        order = sorted(d)
        msgs.append((T0 + k, enc.mt18(len(bands), band, 0, order)))
        msgs.append((T0 + 5 + k, enc.mt26(band, 0, [d[i] for i in order], [0] * len(order), 0)))
    frame = pd.DataFrame(
        {"t": [t - T0 for t, _ in msgs], "gnss_time_s": [t + 1.125 for t, _ in msgs], "prn": 137,
         "message_hex": [m.hex().upper() for _, m in msgs]}
    )  # fmt: skip
    return SbasCorrections.from_stream(frame)


def _zenith(sb: SbasCorrections, lat: float, lon: float) -> tuple[bool, float]:
    cov, d, _ = sb.iono(
        np.radians([lat]),
        np.radians([lon]),
        np.zeros(1),
        np.radians([90.0]),
        np.array([T0 + 20.0]),
        np.array([1.57542e9]),
    )
    return bool(cov[0]), float(d[0])


def test_polar_bands_located() -> None:
    for band, sign, first85 in ((9, 1, -180), (10, -1, -170)):
        la, lo = band_igps(band)
        assert la.size == 192
        got = [(int(la[i - 1]), int(lo[i - 1])) for i in (1, 72, 73, 108, 109, 145, 180, 181, 192)]
        want = [(60, -180), (60, 175), (65, -180), (65, 170), (70, -180), (75, -180), (75, 170), (85, first85),
                (85, first85 + 330)]  # fmt: skip
        assert got == [(sign * a, b) for a, b in want]
    # band 9's 65° and 75° IGPs are bands 0–8's points: the same key
    la9, lo9 = band_igps(9)
    la8, lo8 = band_igps(8)
    assert igp_key(la9[[104]], lo9[[104]])[0] == igp_key(np.array([65]), np.array([140]))[0]
    assert ((la8 == 65) & (lo8 == 140)).any() and (la9[104], lo9[104]) == (65, 140)


def test_between_55_and_60_the_5_degree_cell_uses_the_60_degree_row() -> None:
    # user at 58 N 141 E, zenith: x = 0.2, y = 0.6 in the cell 55–60 N, 140–145 E
    sb = _grid({8: {_igp(8, 55, 140): 2.0, _igp(8, 55, 145): 3.0}, 9: {_igp(9, 60, 145): 9.0, _igp(9, 60, 140): 4.0}})
    cov, d = _zenith(sb, 58.0, 141.0)
    # 0.8·0.4·2 + 0.2·0.4·3 + 0.2·0.6·9 + 0.8·0.6·4 = 0.64 + 0.24 + 1.08 + 1.92
    assert cov and d == pytest.approx(3.88)


def test_between_60_and_75_the_cells_are_5_by_10_degrees() -> None:
    # user at 62 N 143 E, zenith: cell 60–65 N, 140–150 E, x = 0.3, y = 0.4
    igps = {_igp(9, 60, 140): 1.0, _igp(9, 60, 150): 2.0, _igp(9, 65, 150): 3.0, _igp(9, 65, 140): 4.0,
            _igp(9, 60, 145): 50.0}  # fmt: skip  # a 60° IGP between the corners: not a corner of the wide cell
    cov, d = _zenith(_grid({9: igps}), 62.0, 143.0)
    # 0.7·0.6·1 + 0.3·0.6·2 + 0.3·0.4·3 + 0.7·0.4·4 = 0.42 + 0.36 + 0.36 + 1.12
    assert cov and d == pytest.approx(2.26)
    # southern: the same cell mirrored in band 10 (SW corner at 65 S)
    south = {_igp(10, -65, 140): 4.0, _igp(10, -65, 150): 3.0, _igp(10, -60, 150): 2.0, _igp(10, -60, 140): 1.0}
    cov, d = _zenith(_grid({10: south}), -62.0, 143.0)
    # y from 65 S = 0.6: 0.7·0.4·4 + 0.3·0.4·3 + 0.3·0.6·2 + 0.7·0.6·1
    assert cov and d == pytest.approx(1.12 + 0.36 + 0.36 + 0.42)


def test_above_75_degrees_the_grid_is_not_used() -> None:
    igps = {_igp(9, 75, 0): 1.0, _igp(9, 75, 10): 1.0, _igp(9, 85, 0): 1.0, _igp(9, 85, 30): 1.0}
    sb = _grid({9: igps})
    assert not _zenith(sb, 78.0, 5.0)[0]


def test_pierce_point_beyond_the_pole() -> None:
    # user at 80 N 0°, satellite due north at 10° elevation: ψ = 80° − asin(R_e cos 10°/(R_e + h_I))
    psi = np.degrees(np.pi / 2 - np.radians(10.0) - np.arcsin(R_E_M * np.cos(np.radians(10.0)) / (R_E_M + H_I_M)))
    # R_e cos 10°/(R_e + h_I) = 6378.1363·0.9848078/6728.1363 = 0.9335777, asin = 68.99957°
    assert psi == pytest.approx(11.0004, abs=1e-4) and 80.0 + psi > 90.0
    lat, lon, _ = pierce_point(np.radians([80.0]), np.zeros(1), np.zeros(1), np.radians([10.0]))
    # over the pole: latitude 180° − 80° − ψ, longitude λ_u + 180°
    assert np.degrees(lat[0]) == pytest.approx(180.0 - 80.0 - psi, abs=1e-9)
    assert np.degrees(lon[0]) == pytest.approx(180.0, abs=1e-9)
    # the same satellite due south: no crossing, plain branch
    lat_s, lon_s, _ = pierce_point(np.radians([80.0]), np.zeros(1), np.array([np.pi]), np.radians([10.0]))
    assert np.degrees(lat_s[0]) == pytest.approx(80.0 - psi, abs=1e-9) and np.degrees(lon_s[0]) == pytest.approx(0.0)
