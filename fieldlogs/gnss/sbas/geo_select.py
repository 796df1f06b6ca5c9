"""Which GEO's corrections apply at each time, when several are logged (RTCA DO-229 §2.1.1.4.5).

A user applies the complete set of one GEO — its mask, fast, long-term, degradation and
ionospheric messages — and never mixes the corrections of two (their IODPs, IODFs and clock
references are each GEO's own). Here a GEO is *usable* at t when, since its latest MT 0
("do not use this SBAS" — it voids everything the GEO sent before it, ``clock_orbit``):

* a PRN mask (MT 1) was received, at most 600 s before t (Table A-25),
* a degradation message (MT 7) was received, at most 360 s before t (no fast correction
  applies without one), and
* a fast-correction or integrity message (MT 2–6 or 24) was received at most 18 s before t
  (the UDREI time-out of Table A-25: older, no UDREI is in force and none of its corrections
  applies — the GEO has timed out).

The GEO in use is kept as long as it stays usable (no switching back and forth between GEOs
that are both fine); when it stops being usable, the usable GEO with the most recent fast
correction is taken (a tie: the lower PRN), ``preferred`` first when it is usable at the
switch. Usability changes only at a message's reception or at a time-out's expiry, so the
choice is computed once at those instants (a sequence in time, hence the loop over them) and
looked up for any t.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.gnss.constants import FloatArray
from fieldlogs.gnss.sbas.messages import SbasMessages
from fieldlogs.gnss.sbas_tables import TIMEOUT_S

NO_GEO: Final = -1
IntArray = npt.NDArray[np.int64]


def _last(times: FloatArray, at: FloatArray) -> FloatArray:
    """Latest of the sorted ``times`` at or before each of ``at`` (−inf: none)."""
    if times.size == 0:
        return np.full(at.shape, -np.inf)
    i = np.searchsorted(times, at, side="right") - 1
    return np.where(i >= 0, times[np.maximum(i, 0)], -np.inf)


@dataclass(frozen=True)
class GeoInputs:
    """Reception times [GPS s] of one GEO's messages that decide its usability (``fast``: MT 2–6
    and 24)."""

    prn: int
    fast: FloatArray
    mask: FloatArray
    degradation: FloatArray
    mt0: FloatArray
    any: FloatArray
    """Every valid message."""

    @classmethod
    def of(cls, msg: SbasMessages) -> GeoInputs:
        def times(df: pd.DataFrame) -> FloatArray:
            return np.zeros(0) if df.empty else np.unique(df["t_rx"].to_numpy(dtype=float))

        return cls(
            int(msg.geo if msg.geo is not None else NO_GEO),
            np.union1d(times(msg.fast), times(msg.integrity)),
            times(msg.masks),
            times(msg.degradation),
            times(msg.mt0),
            np.unique(np.concatenate([times(f) for f in (msg.fast, msg.integrity, msg.masks, msg.degradation,
                                                         msg.mt10, msg.long_term, msg.igp_mask, msg.iono, msg.mt0)])),
        )  # fmt: skip

    def events(self) -> FloatArray:
        """Instants where the usability may change: receptions and just after each time-out."""
        after = [
            np.nextafter(self.fast + TIMEOUT_S["udrei"], np.inf),
            np.nextafter(self.mask + TIMEOUT_S["mask"], np.inf),
            np.nextafter(self.degradation + TIMEOUT_S["degradation"], np.inf),
        ]
        return np.concatenate([self.fast, self.mask, self.degradation, self.mt0, *after])

    def usable(self, t: FloatArray) -> tuple[npt.NDArray[np.bool_], FloatArray]:
        """Usable at each t (module docstring) and the reception of its latest fast correction."""
        z = _last(self.mt0, t)
        f, m, d = _last(self.fast, t), _last(self.mask, t), _last(self.degradation, t)
        ok = (
            (f > z) & (t - f <= TIMEOUT_S["udrei"])
            & (m > z) & (t - m <= TIMEOUT_S["mask"])
            & (d > z) & (t - d <= TIMEOUT_S["degradation"])
        )  # fmt: skip
        return np.asarray(ok, dtype=bool), f


@dataclass(frozen=True)
class GeoTimeline:
    """The GEO in use from each instant of ``t`` until the next (``NO_GEO``: none)."""

    t: FloatArray
    prn: IntArray
    inputs: tuple[GeoInputs, ...] = ()

    @classmethod
    def build(cls, geos: list[GeoInputs], preferred: int | None = None) -> GeoTimeline:
        if not geos:
            return cls(np.zeros(0), np.zeros(0, dtype=np.int64))
        ev = np.unique(np.concatenate([g.events() for g in geos]))
        ok = np.zeros((ev.size, len(geos)), dtype=bool)
        fresh = np.zeros((ev.size, len(geos)))
        for k, g in enumerate(geos):
            ok[:, k], fresh[:, k] = g.usable(ev)
        prns = np.array([g.prn for g in geos], dtype=np.int64)
        pref = next((k for k, g in enumerate(geos) if g.prn == preferred), -1)
        out = np.full(ev.size, NO_GEO, dtype=np.int64)
        cur = -1
        for i in range(ev.size):  # the choice depends on the previous one (module docstring)
            if cur >= 0 and ok[i, cur]:
                out[i] = prns[cur]
                continue
            cand = np.flatnonzero(ok[i])
            if cand.size == 0:
                cur = -1
                continue
            if pref >= 0 and ok[i, pref]:
                cur = pref
            else:
                best = fresh[i, cand]
                top = cand[best == best.max()]
                cur = int(top[np.argmin(prns[top])])
            out[i] = prns[cur]
        return cls(ev, out, tuple(geos))

    def at(self, t: FloatArray) -> IntArray:
        """The GEO in use at each t (``NO_GEO`` before the first instant or where none is)."""
        tt = np.asarray(t, dtype=float)
        if self.t.size == 0:
            return np.full(tt.shape, NO_GEO, dtype=np.int64)
        i = np.searchsorted(self.t, tt, side="right") - 1
        return np.where(i >= 0, self.prn[np.maximum(i, 0)], NO_GEO).astype(np.int64)

    def for_grid(self, t: FloatArray) -> IntArray:
        """The GEO whose ionospheric grid applies at each t: the one in use, else (no GEO usable
        for clock and orbit, e.g. a GEO sending only MT 18/26) the one whose latest message,
        not voided by an MT 0, is the most recent (the grid's own time-outs then apply)."""
        tt = np.asarray(t, dtype=float)
        out = self.at(tt)
        none = out == NO_GEO
        if none.any() and self.inputs:
            tn = tt[none]
            last = np.stack([np.where(_last(g.any, tn) > _last(g.mt0, tn), _last(g.any, tn), -np.inf)
                             for g in self.inputs], axis=1)  # fmt: skip
            k = np.argmax(last, axis=1)
            prns = np.array([g.prn for g in self.inputs], dtype=np.int64)
            out[none] = np.where(np.isfinite(last.max(axis=1)), prns[k], NO_GEO)
        return out

    def switches(self) -> int:
        """How many times the GEO in use changes from one GEO to another."""
        used = self.prn[self.prn != NO_GEO]
        return int(np.count_nonzero(np.diff(used))) if used.size > 1 else 0
