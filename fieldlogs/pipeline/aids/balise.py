"""Balise unit: initial position from I1→I2 pairs and correction by C balises [S003 §4].

* Power-up: undetermined. I1 then I2 within 10 m of travel → look up (line, station,
  track) → actual and equipment km at I2. Reverse order (I2 first) → ignored. A code not
  in the DB → anomaly, state kept.
* km counts up on a D (or S) telegram, down on U; cab reversals after the pair are
  followed through the signed travel (see :mod:`fieldlogs.pipeline.estimate`).
* C balise: identified from (last initial pair, signal type) and accepted only if the
  travel since that pair's I1 is within ±500 m of the DB's ``dist_from_initial_m``.
  Correction amount = computed km − DB km; the engine turns it into the position-
  correction % = |amount| / distance since the previous correction × 100.

Each fix's uncertainty is ``fix_uncertainty_m`` + ``latency_budget_s`` × the speed at the
telegram: a time stamp off by τ puts the fix v·τ from the balise, which the balise clock check
(:mod:`fieldlogs.pipeline.consistency`) cannot see below its tolerance.

The aid's only state is the pending I1 and the last initial pair (the identification
base of the C balises); it speaks at every telegram.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.config import BaliseConfig
from fieldlogs.pipeline.types import Event, Fix
from schemas.enums import BaliseKind, EventType, FixSource, direction_sign

try:  # to_dict's own boxing of a cell (pandas internals: if a pandas release moves it, the slow path below)
    from pandas.core.dtypes.cast import maybe_box_native  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the installed pandas
    maybe_box_native = None

PairKey = tuple[str, str, str]
Telegram = dict[str, Any]
"""One telegram row (:func:`telegram_rows`)."""


@dataclass
class _Pending:
    i: int
    d: float
    line_code: str


@dataclass
class BaliseDb:
    """Look-up structures built once from the balise table."""

    pairs: dict[PairKey, dict[str, dict[str, Any]]]
    c_balises: dict[tuple[PairKey, str], list[dict[str, Any]]]
    line_codes: set[str]

    @classmethod
    def from_network(cls, network: Network) -> BaliseDb:
        b = network.s003_balises
        pairs: dict[PairKey, dict[str, dict[str, Any]]] = {}
        c_bal: dict[tuple[PairKey, str], list[dict[str, Any]]] = {}
        rows: list[dict[str, Any]] = b.astype(object).where(b.notna(), None).to_dict("records")  # type: ignore[assignment]
        for row in rows:
            key = (str(row["line_code"]), str(row["station_code"]), str(row["track"]))
            if row["kind"] == BaliseKind.C:
                c_bal.setdefault((key, str(row["signal_type"])), []).append(row)
            else:
                pairs.setdefault(key, {})[str(row["kind"])] = row
        lines = set(network.lines["line_code"].astype(str)) | set(b["line_code"].astype(str))
        return cls(pairs, c_bal, lines)


@dataclass
class BaliseAid(StaticAid):
    """Telegrams in time order (module docstring): the balise aid of the engine."""

    db: BaliseDb
    cfg: BaliseConfig
    telegrams: Sequence[Telegram] = field(default=(), repr=False)
    """The run's telegrams of every kind (:func:`telegram_rows`): the aid hears all but ``G``."""
    reader_x_m: float = 0.0
    """The balise reader's position forward of the vehicle's reference point [m]."""
    pending: _Pending | None = None
    last_pair: tuple[PairKey, float] | None = None
    """(pair key, travel distance at its I1)."""
    _s: float = 0.0
    _u: float | None = None
    """Uncertainty of the fix of the telegram being handled (fix + latency budget × speed)."""
    name = "balise"
    priority = Priority.TELEGRAM

    def observations(self) -> Iterator[Observation]:
        # ETCS groups are the balise-group aid's
        return telegram_observations(self.telegrams, lambda row: row["kind"] != BaliseKind.G)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        self._u = self.cfg.fix_uncertainty_m + self.cfg.latency_budget_s * float(view.travel.v[view.i])
        evs, fix = self.on_telegram(obs.payload, view.i, view.t, view.d, view.s, view.motion, view.estimate, view.km)
        return Outcome(evs, fix if evs else None)

    def on_telegram(
        self,
        tel: dict[str, Any],
        i: int,
        t: float,
        d: float,
        s: float,
        motion: int,
        estimate: Fix | None,
        km_now: float | None,
    ) -> tuple[list[Event], Fix | None]:
        """Handle one telegram at time ``t`` (cycle ``i``, travel ``d``, signed travel ``s``);
        returns events and a new fix (or None)."""
        self._s = s
        kind = str(tel.get("kind") or "")
        if kind == BaliseKind.I1:
            return self._on_i1(tel, i, t, d)
        if kind == BaliseKind.I2:
            return self._on_i2(tel, i, t, d, motion, estimate, km_now)
        if kind == BaliseKind.C:
            return self._on_c(tel, i, t, d, motion, estimate, km_now)
        return [Event(t, EventType.BALISE_ANOMALY, km_now, detail={"reason": f"unknown telegram kind {kind!r}"})], None

    def _on_i1(self, tel: dict[str, Any], i: int, t: float, d: float) -> tuple[list[Event], Fix | None]:
        line = _s(tel.get("line_code"))
        if line is None or line not in self.db.line_codes:
            self.pending = None
            return [
                Event(
                    t, EventType.BALISE_ANOMALY, detail={"reason": "unknown line code", "kind": "I1", "line_code": line}
                )
            ], None
        self.pending = _Pending(i, d, line)
        return [], None

    def _on_i2(
        self, tel: dict[str, Any], i: int, t: float, d: float, motion: int, estimate: Fix | None, km_now: float | None
    ) -> tuple[list[Event], Fix | None]:
        station, track = _s(tel.get("station_code")), _s(tel.get("track"))
        pending, self.pending = self.pending, None
        if pending is None or d - pending.d > self.cfg.pair_max_travel_m:
            why = (
                "I2 without a preceding I1 (reverse order or missed I1)"
                if pending is None
                else f"I2 {d - pending.d:.1f} m after I1 (limit {self.cfg.pair_max_travel_m:g} m)"
            )
            return [
                Event(
                    t, EventType.PAIR_IGNORED, km_now, detail={"reason": why, "station_code": station, "track": track}
                )
            ], None
        key = (pending.line_code, station or "", track or "")
        pair = self.db.pairs.get(key)
        if pair is None or "I2" not in pair or "I1" not in pair:
            return [
                Event(
                    t,
                    EventType.BALISE_ANOMALY,
                    km_now,
                    detail={
                        "reason": "initial pair not in DB",
                        "line_code": key[0],
                        "station_code": key[1],
                        "track": key[2],
                    },
                )
            ], None
        i2 = pair["I2"]
        km_db, km_eq = float(i2["km_actual_m"]), float(i2["km_equipment_m"])
        k = direction_sign(key[2]) * (1 if motion >= 0 else -1)
        at_ref = -k * self.reader_x_m  # the reader is x_r ahead of the reference point (geometry.py)
        fix = Fix(
            t,
            self._s,
            d,
            km_db + at_ref,
            km_eq + at_ref,
            key[0],
            key[2],
            k,
            FixSource.BALISE,
            self.cfg.fix_uncertainty_m if self._u is None else self._u,
            t_ref=t,
        )
        self.last_pair = (key, pending.d)
        detail = {"balise_id": i2["balise_id"], "line_code": key[0], "station_code": key[1], "track": key[2]}
        if estimate is None or km_now is None or estimate.line_code != key[0]:
            return [Event(t, EventType.INITIAL_POSITION, km_db, detail=detail)], fix
        amount = km_now - at_ref - km_db  # computed km at the reader − DB km
        return [Event(t, EventType.BALISE_CORRECTION, km_db, amount, detail={**detail, "kind": "I2"})], fix

    def _on_c(
        self,
        tel: dict[str, Any],
        i: int,
        t: float,
        d: float,
        motion: int,
        estimate: Fix | None,
        km_now: float | None,
    ) -> tuple[list[Event], Fix | None]:
        sig = _s(tel.get("signal_type")) or ""
        if estimate is None or self.last_pair is None or km_now is None:
            return [
                Event(t, EventType.C_BALISE_IGNORED, detail={"reason": "no initial pair yet", "signal_type": sig})
            ], None
        key, d_i1 = self.last_pair
        if estimate.k * motion != direction_sign(key[2]):
            return [
                Event(
                    t,
                    EventType.C_BALISE_IGNORED,
                    km_now,
                    detail={"reason": "running against the direction of the governing pair", "signal_type": sig},
                )
            ], None
        travelled = d - d_i1
        cands = self.db.c_balises.get((key, sig), [])
        hits = [c for c in cands if abs(travelled - float(c["dist_from_initial_m"])) <= self.cfg.id_window_m]
        base = {"signal_type": sig, "pair": "/".join(key), "travelled_m": round(travelled, 2)}
        if len(hits) != 1:
            reason = (
                "no C balise of this signal type within the window"
                if not hits
                else "ambiguous: several C balises within the window"
            )
            return [
                Event(
                    t,
                    EventType.BALISE_ANOMALY,
                    km_now,
                    detail={**base, "reason": reason, "candidates": [c["balise_id"] for c in hits]},
                )
            ], None
        c = hits[0]
        km_db, km_eq = float(c["km_actual_m"]), float(c["km_equipment_m"])
        at_ref = -estimate.k * self.reader_x_m
        fix = Fix(
            t,
            self._s,
            d,
            km_db + at_ref,
            km_eq + at_ref,
            estimate.line_code,
            estimate.track,
            estimate.k,
            FixSource.BALISE,
            self.cfg.fix_uncertainty_m if self._u is None else self._u,
            t_ref=t,
        )
        return [
            Event(
                t,
                EventType.BALISE_CORRECTION,
                km_db,
                km_now - at_ref - km_db,
                detail={**base, "balise_id": c["balise_id"], "kind": "C"},
            )
        ], fix


def telegram_observations(rows: Sequence[Telegram], keep: Callable[[Telegram], bool]) -> Iterator[Observation]:
    """One observation per telegram row ``keep`` accepts, at its t."""
    for row in rows:
        if keep(row):
            yield Observation(float(row["t"]), row)


def telegram_rows(tel: pd.DataFrame) -> list[dict[str, Any]]:
    """The rows of ``tel`` as dicts, NaN/NA cells as None, every cell a native Python value:
    ``tel.astype(object).where(tel.notna(), None).to_dict("records")``, made column by column —
    each column's ``to_numpy(dtype=object)`` (the values ``astype(object)`` gives), None where
    ``isna``, every other cell boxed by pandas' own ``maybe_box_native`` as ``to_dict`` boxes
    object columns — at a fifth of the cost on a run's few rows of extension dtypes (the sample
    runs' streams, 6–15 rows × 11 columns: ≈ 0.7 ms instead of ≈ 3.8 ms by ``astype``/``where``;
    made once a run for every balise aid, :attr:`~fieldlogs.pipeline.aids.registry.RunContext.telegrams`)."""
    if maybe_box_native is None or not tel.columns.is_unique or tel.shape[1] == 0:
        return tel.astype(object).where(tel.notna(), None).to_dict("records")  # type: ignore[return-value]
    names = tel.columns.tolist()
    missing = tel.isna().to_numpy().tolist()
    cols = [col.to_numpy(dtype=object).tolist() for _name, col in tel.items()]
    return [
        {k: None if m else maybe_box_native(v) for k, v, m in zip(names, vals, miss, strict=True)}
        for vals, miss in zip(zip(*cols, strict=True), missing, strict=True)
    ]


def _s(v: Any) -> str | None:
    if v is None or (isinstance(v, float) and v != v) or v is pd.NA:
        return None
    s = str(v).strip()
    return s or None
