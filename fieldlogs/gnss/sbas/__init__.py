"""SBAS/MSAS L1 corrections (RTCA DO-229 Appendix A) for the GNSS core [S002].

* ``bits`` — bit fields and the CRC-24Q (DO-229's look-up tables and IGP bands, which the
  simulator reads too, are ``fieldlogs.gnss.sbas_tables``, outside this package);
* ``decode`` — MT 0, 1, 2–7, 9, 10, 12, 17, 18, 24–28 → frames, vectorised per type;
* ``messages`` — a ``gnss_sbas`` stream screened (length, PRN, preamble, CRC) and decoded;
* ``clock_orbit`` — fast + long-term corrections and σ_flt per observation row;
* ``grid`` — the ionospheric grid at the pierce point and σ_UIRE;
* ``delta_udre`` — δUDRE of MT 27 (service regions) or MT 28 (covariance) in σ_flt;
* ``geo_select`` — which GEO's complete set applies when several are logged.

The encoder (written from the standard's tables apart from the decoder, so that each checks
the other) and the simulated stream are the simulator's: ``fieldlogs.simulate.gnss.sbas_encode``
and ``fieldlogs.simulate.gnss.sbas_stream``.

:class:`SbasCorrections` (every GEO's :class:`GeoSet` and the timeline of the GEO in use) is what
the core takes (``observables.build_epochs`` and
``apply_geometry``, ``position.position_run(sbas=...)``).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.gnss.constants import BoolArray, FloatArray, StrArray
from fieldlogs.gnss.corrections import RowCorrections, no_corrections
from fieldlogs.gnss.sbas.clock_orbit import ClockOrbitTables
from fieldlogs.gnss.sbas.delta_udre import DeltaUdre
from fieldlogs.gnss.sbas.geo_select import NO_GEO, GeoInputs, GeoTimeline
from fieldlogs.gnss.sbas.grid import IonoGrid
from fieldlogs.gnss.sbas.messages import SbasMessages, read_geos, read_messages


@dataclass(frozen=True)
class GeoSet:
    """One GEO's decoded messages and the tables built from them."""

    messages: SbasMessages
    clock_orbit: ClockOrbitTables
    grid: IonoGrid
    delta_udre: DeltaUdre

    @classmethod
    def of(cls, msg: SbasMessages) -> GeoSet:
        return cls(msg, ClockOrbitTables.build(msg), IonoGrid.build(msg), DeltaUdre.build(msg))


@dataclass
class SbasCorrections:
    """Every logged GEO's decoded corrections and which GEO applies when (``geo_select``)."""

    geos: dict[int, GeoSet]
    timeline: GeoTimeline
    counts: dict[str, int] = field(default_factory=dict)
    """Observation rows by outcome of the last ``rows`` call (``clock_orbit._combine``; rows at
    a time no GEO is usable: ``no_usable_geo``)."""
    used: dict[int, int] = field(default_factory=dict)
    """Observation rows of the last ``rows`` call by the GEO whose corrections applied."""
    dropped: Counter[str] = field(default_factory=Counter)
    """Stream rows dropped by reason (``messages`` module docstring)."""

    @classmethod
    def from_stream(cls, frame: pd.DataFrame | None, prn: int | None = None) -> SbasCorrections:
        """All GEOs of the stream (``prn``: only that one; None: each, chosen per time)."""
        if prn is not None:
            one = read_messages(frame, prn)
            msgs = {prn: one} if one.n_valid else {}
            dropped = one.dropped
        else:
            msgs = read_geos(frame)
            dropped = next(iter(msgs.values())).dropped if msgs else read_messages(frame).dropped
        geos = {g: GeoSet.of(m) for g, m in msgs.items()}
        return cls(geos, GeoTimeline.build([GeoInputs.of(m) for m in msgs.values()]), dropped=Counter(dropped))

    @property
    def empty(self) -> bool:
        return not self.geos

    @property
    def messages(self) -> SbasMessages:
        """The messages of the GEO used most (the only one with one GEO; ``primary``)."""
        if not self.geos:
            return SbasMessages(None, dropped=Counter(self.dropped))
        return self.geos[self.primary].messages

    @property
    def primary(self) -> int:
        """The GEO in use for the longest time (the lower PRN on a tie)."""
        t, p = self.timeline.t, self.timeline.prn
        if t.size < 2:
            return min(self.geos)
        span = np.diff(t)
        best, best_s = min(self.geos), -1.0
        for g in sorted(self.geos):
            s = float(span[p[:-1] == g].sum())
            if s > best_s:
                best, best_s = g, s
        return best

    def active(self, t: FloatArray) -> npt.NDArray[np.int64]:
        """The GEO whose corrections apply at each t (``NO_GEO``: none usable)."""
        return self.timeline.at(t)

    def rows(self, sat: StrArray, t: FloatArray, iode: FloatArray) -> RowCorrections:
        """Fast + long-term corrections and σ_flt of observation rows, each from the GEO in use
        at its time (``clock_orbit``, ``geo_select``)."""
        tt = np.asarray(t, dtype=float)
        n = tt.size
        out = no_corrections(n)
        out = RowCorrections(
            out.present, out.prc_m, out.dpos_m, out.dclock_s, out.sigma_m, out.usable, out.covers_atmosphere,
            np.full(n, np.nan), np.zeros(n, dtype=bool),
        )  # fmt: skip
        geo = self.active(tt)
        counts: dict[str, int] = {"no_usable_geo": int((geo == NO_GEO).sum())}
        self.used = {}
        s, io = np.asarray(sat, dtype=str), np.asarray(iode, dtype=float)
        for g, gs in self.geos.items():
            sel = np.flatnonzero(geo == g)
            if not sel.size:
                continue
            part, c = gs.clock_orbit.rows(s[sel], tt[sel], io[sel])
            for name in ("present", "prc_m", "dpos_m", "dclock_s", "sigma_m", "usable", "covers_atmosphere",
                         "udre_sigma_m", "udre_rss"):  # fmt: skip
                getattr(out, name)[sel] = getattr(part, name)
            for k, v in c.items():
                counts[k] = counts.get(k, 0) + v
            self.used[g] = int(sel.size)
        for k in ("corrected", "refused_udrei", "no_fast_correction", "no_long_term", "no_degradation"):
            counts.setdefault(k, 0)
        counts.setdefault("udrei_timed_out", 0)
        self.counts = counts
        return out

    def flt_sigma(
        self,
        sigma_m: FloatArray,
        udre_sigma_m: FloatArray,
        rss: BoolArray,
        sat: StrArray,
        t: FloatArray,
        lat_rad: FloatArray,
        lon_rad: FloatArray,
        los: FloatArray,
    ) -> FloatArray:
        """σ_flt of rows (flat) with δUDRE of the GEO in use (``delta_udre``): from σ_flt at
        δUDRE = 1, σ_flt + σ_UDRE(δUDRE − 1), or √(σ²_flt + σ²_UDRE(δUDRE² − 1)) with RSS_UDRE."""
        tt = np.asarray(t, dtype=float)
        delta = np.ones(tt.size)
        geo = self.active(tt)
        lat, lon = np.degrees(np.asarray(lat_rad, dtype=float)), np.degrees(np.asarray(lon_rad, dtype=float))
        s = np.asarray(sat, dtype=str)
        for g, gs in self.geos.items():
            sel = np.flatnonzero((geo == g) & np.isfinite(udre_sigma_m))
            if sel.size and not gs.delta_udre.empty:
                delta[sel] = gs.delta_udre.factor(s[sel], tt[sel], lat[sel], lon[sel], los[sel])
        su = np.nan_to_num(np.asarray(udre_sigma_m, dtype=float), nan=0.0)
        lin = sigma_m + su * (delta - 1.0)
        root = np.sqrt(np.maximum(sigma_m**2 + su**2 * (delta**2 - 1.0), 0.0))
        return np.asarray(np.where(rss, root, lin), dtype=float)

    def iono(
        self,
        lat_rad: FloatArray,
        lon_rad: FloatArray,
        az_rad: FloatArray,
        el_rad: FloatArray,
        t: FloatArray,
        freq_hz: FloatArray,
    ) -> tuple[BoolArray, FloatArray, FloatArray]:
        """(covered, slant delay [m], σ_UIRE [m]) from the grid of the GEO in use (``grid``;
        ``GeoTimeline.for_grid``)."""
        shape = np.broadcast(*(np.asarray(v) for v in (lat_rad, lon_rad, az_rad, el_rad, t, freq_hz))).shape
        b = [np.broadcast_to(np.asarray(v, dtype=float), shape).ravel() for v in
             (lat_rad, lon_rad, az_rad, el_rad, t, freq_hz)]  # fmt: skip
        n = b[0].size
        cov, delay, sigma = np.zeros(n, dtype=bool), np.full(n, np.nan), np.full(n, np.nan)
        geo = self.timeline.for_grid(b[4])
        for g, gs in self.geos.items():
            sel = np.flatnonzero(geo == g)
            if sel.size:
                cov[sel], delay[sel], sigma[sel] = gs.grid.slant(*(v[sel] for v in b))
        return cov.reshape(shape), delay.reshape(shape), sigma.reshape(shape)


__all__ = ["GeoSet", "SbasCorrections", "read_geos", "read_messages"]
