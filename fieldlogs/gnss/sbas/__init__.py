"""SBAS/MSAS L1 corrections (RTCA DO-229 Appendix A) for the GNSS core [S002].

* ``bits`` — bit fields and the CRC-24Q; ``tables`` — DO-229's look-up tables and IGP bands;
* ``encode`` — an encoder written from the standard's tables (simulator and tests);
* ``decode`` — MT 0, 1, 2–5, 6, 7, 10, 18, 24, 25, 26 → frames, vectorised per type;
* ``messages`` — a ``gnss_sbas`` stream screened (length, PRN, preamble, CRC) and decoded;
* ``clock_orbit`` — fast + long-term corrections and σ_flt per observation row;
* ``grid`` — the ionospheric grid at the pierce point and σ_UIRE;
* ``simulate`` — a ``gnss_sbas`` stream consistent with a simulated run's errors.

:class:`SbasCorrections` is what the core takes (``observables.build_epochs`` and
``apply_geometry``, ``position.position_run(sbas=...)``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from fieldlogs.gnss.constants import BoolArray, FloatArray, StrArray
from fieldlogs.gnss.corrections import RowCorrections
from fieldlogs.gnss.sbas.clock_orbit import ClockOrbitTables
from fieldlogs.gnss.sbas.grid import IonoGrid
from fieldlogs.gnss.sbas.messages import SbasMessages, read_messages


@dataclass
class SbasCorrections:
    """One GEO's decoded corrections, ready to apply (package docstring)."""

    messages: SbasMessages
    clock_orbit: ClockOrbitTables
    grid: IonoGrid
    counts: dict[str, int] = field(default_factory=dict)
    """Observation rows by outcome of the last ``rows`` call (``clock_orbit._combine``)."""

    @classmethod
    def from_stream(cls, frame: pd.DataFrame | None, prn: int | None = None) -> SbasCorrections:
        msg = read_messages(frame, prn)
        return cls(msg, ClockOrbitTables.build(msg), IonoGrid.build(msg))

    @property
    def empty(self) -> bool:
        return self.messages.n_valid == 0

    def rows(self, sat: StrArray, t: FloatArray, iode: FloatArray) -> RowCorrections:
        """Fast + long-term corrections and σ_flt of observation rows (``clock_orbit``)."""
        out, self.counts = self.clock_orbit.rows(sat, t, iode)
        return out

    def iono(
        self,
        lat_rad: FloatArray,
        lon_rad: FloatArray,
        az_rad: FloatArray,
        el_rad: FloatArray,
        t: FloatArray,
        freq_hz: FloatArray,
    ) -> tuple[BoolArray, FloatArray, FloatArray]:
        """(covered, slant delay [m], σ_UIRE [m]) from the grid (``grid``)."""
        return self.grid.slant(lat_rad, lon_rad, az_rad, el_rad, t, freq_hz)


__all__ = ["SbasCorrections", "read_messages"]
