"""An S003 I2 telegram as track evidence among network candidates [S003 §4; SPEC §8.3].

An I2 telegram names its station and track; the DB's initial pair of (line, station, track)
gives the balise's km, and so its place on one network track (:meth:`TrackLines.locate`). The
balise aid (:mod:`fieldlogs.pipeline.aids.balise`) takes a position from the pair only, I1 then
I2 within ``balise.pair_max_travel_m`` (the order gives the direction): an I2 read without its
I1 — a start between the two balises, an I1 missed — is ignored there (``pair_ignored``). Its
identity alone still says which track the reader was on, as an ETCS group's does
(:mod:`fieldlogs.pipeline.aids.balise_group`).

While the estimate is ambiguous, for each line of the candidates' tracks whose pair
(line, station, track) the DB holds, the balise lies on network track T at pos p_b. A candidate
h holds the read when it is on T and its reader, dead-reckoned to now (pos_h + kp·x_r, x_r the
reader forward of the reference point), lies within m + ``extra_m`` + u of p_b (m the margin, u
the telegram's own uncertainty ``balise.fix_uncertainty_m`` + ``balise.latency_budget_s`` ×
speed). A reader passes over a balise only on the balise's track, so when some but not all
candidates hold the read, the one holding it is kept — placed at the balise, pos = p_b − kp·x_r,
an absolute fix with uncertainty u (``track_resolved``, evidence ``balise``) — and the others are
dropped. A read no candidate holds changes nothing here (the balise aid reports what it makes
of it).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.aids.balise import BaliseDb, Telegram, telegram_observations
from fieldlogs.pipeline.aids.topology import with_hyps
from fieldlogs.pipeline.config import BaliseConfig, MarginConfig
from fieldlogs.pipeline.hypotheses import TrackLines, after_switch_m
from fieldlogs.pipeline.positions import margin_m
from fieldlogs.pipeline.types import Event, Fix, Hypothesis
from schemas.enums import BaliseKind, EventType, FixSource


@dataclass(eq=False)
class TrackBaliseAid(StaticAid):
    """I2 telegrams as track evidence (module docstring)."""

    db: BaliseDb
    lines: TrackLines
    cfg: BaliseConfig
    margin: MarginConfig
    telegrams: Sequence[Telegram] = field(repr=False)
    """The run's telegrams of every kind (:func:`~fieldlogs.pipeline.aids.balise.telegram_rows`): the aid hears I2."""
    reader_x_m: float = 0.0
    name = "track_balise"
    priority = Priority.TELEGRAM

    def observations(self) -> Iterator[Observation]:
        return telegram_observations(self.telegrams, lambda row: row["kind"] == BaliseKind.I2)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        if fix is None or len(fix.hyps) < 2:
            return Outcome()
        tel: dict[str, Any] = obs.payload
        station, track = str(tel.get("station_code") or ""), str(tel.get("track") or "")
        u = self.cfg.fix_uncertainty_m + self.cfg.latency_budget_s * float(view.travel.v[view.i])
        m = float(margin_m(fix, view.d, view.travel.allowance_at(view.t), self.margin))
        hyps = [replace(h, pos_m=h.pos_m + h.kp * (view.s - fix.s_ref)) for h in fix.hyps]
        held: list[tuple[Hypothesis, float, str]] = []
        for line in sorted({self.lines[h.track_id].line_code for h in hyps} - {""}):
            i2 = self.db.pairs.get((line, station, track), {}).get("I2")
            at = None if i2 is None else self.lines.locate(line, track, float(i2["km_actual_m"]))
            if at is None:
                continue
            tl, p_b = at
            held += [
                (h, p_b, str(i2["balise_id"]))  # type: ignore[index]
                for h in hyps
                if h.track_id == tl.track_id and abs(h.pos_m + h.kp * self.reader_x_m - p_b) <= m + h.extra_m + u
            ]
        if len(held) != 1:
            return Outcome()  # none holds it, or it cannot tell them apart
        h, p_b, balise_id = held[0]
        nan = float("nan")
        new = Fix(view.t, view.s, view.d, nan, nan, "", "", 1, FixSource.BALISE, u, t_ref=view.t)
        new = replace(
            with_hyps(new, [replace(h, pos_m=p_b - h.kp * self.reader_x_m, extra_m=0.0)], view.t, view.s, self.lines),
            carried=False,
        )
        detail: dict[str, Any] = {
            "evidence": "balise",
            "balise_id": balise_id,
            "track_id": h.track_id,
            "candidates": [c.track_id for c in fix.hyps],
            "after_switch_m": after_switch_m(fix.hyps, view.d),
            "switch_id": h.switch_id,
        }
        return Outcome([Event(view.t, EventType.TRACK_RESOLVED, new.km_m, detail=detail)], new)
