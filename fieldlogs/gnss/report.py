"""``trainpos gnss position``: every epoch of a run on one line/track, constrained and not [S002].

The solutions are those of the pipeline's GNSS aid (:func:`fieldlogs.gnss.ontrack.solve_on_track`,
no prior), optionally under a sky mask — the paper's experiment of blocking the west half of the
sky on any run. One row per receiver-epoch:

* the constrained solution: ``status`` (``ok`` or why not: too few satellites, poor geometry,
  no on-track solution, a fault that could not be excluded, not converged), ``available``
  (ok and the antenna-distance check passed), ``km_m`` of the vehicle's reference point,
  ``uncertainty_m`` (the stated bound U), ``sigma_m`` (1σ along the track), ``residual_rms_m``
  of the used pseudoranges, ``clock_aided``;
* the satellites: ``used``, ``excluded`` (by fault detection and exclusion, or without an
  on-track solution) and ``not_used`` with the reason of each (elevation, C/N0 or sky mask,
  pre-checks, no ephemeris, system not selected);
* the unconstrained (x, y, z, clock) least squares beside it: ``lsq_available`` (≥ 4
  satellites, PDOP ≤ ``gnss.max_pdop``), ``lsq_n_used``, ``lsq_pdop``, its geodetic position
  and its distance from the track.

With SBAS/MSAS messages in the run (``gnss_sbas``) the report says which GEO, how many
messages were used or dropped and how many observation rows were corrected (``sbas``).

Facing (which way the F end faces, for the antennas' offsets from the reference point): given,
the pipeline's, or — ``direction`` 0 — from the fixes' motion (``fieldlogs.gnss.facing``);
unknown when they barely move: both facings solved, km their mean, U widened by half their
difference (``_either_facing``).

Availability: the share of epochs (receivers' epochs within 20 ms are one epoch) with an
available constrained solution from at least one receiver, against the share with an
available unconstrained one, and the same per receiver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from fieldlogs.gnss.config import GnssConfig, position_config
from fieldlogs.gnss.facing import facing_from_motion
from fieldlogs.gnss.geodesy import ecef_to_geodetic
from fieldlogs.gnss.gis import GisTrack
from fieldlogs.gnss.observables import FLAG_NAMES, Epochs
from fieldlogs.gnss.ontrack import TrackSolutions, solve_on_track
from fieldlogs.gnss.position import PositionConfig
from fieldlogs.gnss.runinputs import RunGnss
from fieldlogs.gnss.skymask import SkyMask

if TYPE_CHECKING:
    from fieldlogs.gnss.sbas import SbasCorrections

#: JSON ``facing`` of a direction (0: unknown, ``fieldlogs.gnss.facing``).
FACING_NAMES = {1: "increasing_km", -1: "decreasing_km", 0: "unknown"}
#: Flags of an FDE decision (reported as ``excluded``, the others as ``not_used``).
_FDE = ("fde_excluded", "no_track_solution")


@dataclass
class GnssPositionReport:
    """The command's result (module docstring); ``to_json`` is its JSON."""

    run_id: str
    line_code: str
    track: str
    track_source: str
    direction: int
    """+1 / −1: the F end faces increasing / decreasing km; 0: unknown (both facings merged)."""
    facing_source: str
    sky_mask: str
    systems: tuple[str, ...]
    epochs: pd.DataFrame = field(repr=False)
    availability: dict[str, Any] = field(default_factory=dict)
    sbas: dict[str, Any] | None = None
    """SBAS/MSAS use (``sbas_summary``), None when the run has no valid message or it is off."""

    def to_json(self) -> dict[str, Any]:
        rows = self.epochs.astype(object).where(self.epochs.notna(), None).to_dict("records")
        return {
            "run": self.run_id,
            "line_code": self.line_code,
            "track": self.track,
            "track_source": self.track_source,
            "facing": FACING_NAMES[self.direction],
            "facing_source": self.facing_source,
            "sky_mask": self.sky_mask,
            "systems": list(self.systems),
            "availability": self.availability,
            "sbas": self.sbas,
            "epochs": rows,
        }


def _sat_lists(ep: Epochs) -> tuple[list[list[str]], list[list[str]], list[dict[str, str]]]:
    """Per epoch row: satellites used, excluded by FDE, and the others with their reasons."""
    used, excluded, other = [], [], []
    for e in range(ep.t.size):  # per output row: formatting, not arithmetic
        sats, flags, present = ep.sat[e], ep.flags[e], ep.present[e]
        used.append(sorted(str(s) for s in sats[present & (flags == 0)]))
        ex: list[str] = []
        why: dict[str, str] = {}
        for s, f in zip(sats[present & (flags != 0)], flags[present & (flags != 0)], strict=True):
            names = [n for bit, n in FLAG_NAMES.items() if int(f) & bit]
            if any(n in _FDE for n in names):
                ex.append(str(s))
            else:
                why[str(s)] = "+".join(names)
        excluded.append(sorted(ex))
        other.append(dict(sorted(why.items())))
    return used, excluded, other


def _lsq_columns(tb: pd.DataFrame, track: GisTrack) -> pd.DataFrame:
    pos = tb[["lsq_x_m", "lsq_y_m", "lsq_z_m"]].to_numpy(dtype=float)
    ok = tb["lsq_available"].to_numpy(bool) & np.all(np.isfinite(pos), axis=1)
    cols = ["lsq_lat", "lsq_lon", "lsq_h_m", "lsq_km_m", "lsq_offset_m"]
    out = pd.DataFrame(np.nan, index=tb.index, columns=cols)
    if ok.any():
        lat, lon, h = ecef_to_geodetic(pos[ok])
        s = track.line.project(pos[ok])
        out.loc[ok, "lsq_lat"], out.loc[ok, "lsq_lon"], out.loc[ok, "lsq_h_m"] = np.degrees(lat), np.degrees(lon), h
        out.loc[ok, "lsq_km_m"] = track.km_of_s(s)
        out.loc[ok, "lsq_offset_m"] = np.linalg.norm(pos[ok] - track.line.point(s), axis=1)
    return out


def _availability(tb: pd.DataFrame) -> dict[str, Any]:
    per_epoch = tb.groupby("epoch")[["ok", "lsq_available"]].any()
    by_rx = tb.groupby("receiver")[["ok", "lsq_available"]].mean()
    return {
        "epochs": len(per_epoch),
        "constrained": float(per_epoch["ok"].mean()) if len(per_epoch) else 0.0,
        "unconstrained": float(per_epoch["lsq_available"].mean()) if len(per_epoch) else 0.0,
        "by_receiver": {
            str(r): {"epochs": int((tb["receiver"] == r).sum()), "constrained": float(v.ok),
                     "unconstrained": float(v.lsq_available)}
            for r, v in by_rx.iterrows()
        },
    }  # fmt: skip


#: Columns of ``GnssPositionReport.epochs``, in order.
COLUMNS = (
    "t", "gnss_time_s", "receiver", "status", "available", "km_m", "uncertainty_m", "sigma_m", "residual_rms_m",
    "n_used", "used", "excluded", "not_used", "clock_aided", "antenna_distance_ok", "lsq_available", "lsq_n_used",
    "lsq_pdop", "lsq_lat", "lsq_lon", "lsq_h_m", "lsq_km_m", "lsq_offset_m",
)  # fmt: skip


def _table(sols: TrackSolutions, track: GisTrack) -> pd.DataFrame:
    tb = sols.table.copy()
    tb["ok"] = tb["ok"].astype(bool)
    used, excluded, other = _sat_lists(sols.result.observations)
    tb["used"], tb["excluded"] = used, excluded
    tb["not_used"] = pd.Series(other, index=tb.index, dtype=object)
    tb["available"] = tb["ok"]
    tb = pd.concat([tb, _lsq_columns(tb, track)], axis=1)
    if "antenna_distance_ok" not in tb:
        tb["antenna_distance_ok"] = True
    return tb


def _either_facing(plus: pd.DataFrame, minus: pd.DataFrame) -> pd.DataFrame:
    """Facing unknown: the rows solved with d = +1 and d = −1 as one. The reference point lies
    at km₊ or km₋ (the antennas' along/lateral offsets mirrored): km = (km₊ + km₋)/2 with the
    bound U = max(U₊, U₋) + |km₊ − km₋|/2 (and σ likewise), available only where both are."""
    tb = plus.copy()
    m = minus.reindex(plus.index)
    ka, kb = plus["km_m"].to_numpy(float), m["km_m"].to_numpy(float)
    half = 0.5 * np.abs(ka - kb)
    tb["km_m"] = 0.5 * (ka + kb)
    for col in ("uncertainty_m", "sigma_m"):
        tb[col] = np.fmax(plus[col].to_numpy(float), m[col].to_numpy(float)) + half
    both = plus["ok"].to_numpy(bool) & m["ok"].to_numpy(bool, na_value=False)
    tb["ok"] = tb["available"] = both
    tb["status"] = np.where(plus["ok"].to_numpy(bool), m["status"].to_numpy(object), plus["status"].to_numpy(object))
    return tb


def _solve(
    g: RunGnss, track: GisTrack, direction: int, pc: PositionConfig, sky_mask: SkyMask | None, cab: pd.DataFrame | None
) -> tuple[pd.DataFrame, int, str | None]:
    """(report rows, facing, how it was decided — None when given); ``direction`` 0: from the fixes."""
    if direction != 0:
        return _table(solve_on_track(g, track, direction, pc, sky_mask=sky_mask), track), direction, None
    plus = solve_on_track(g, track, 1, pc, sky_mask=sky_mask)
    decision = facing_from_motion(plus.best.reset_index(), cab)
    if decision.direction == 1:
        return _table(plus, track), 1, decision.source
    minus = _table(solve_on_track(g, track, -1, pc, sky_mask=sky_mask), track)
    if decision.direction == -1:
        return minus, -1, decision.source
    return _either_facing(_table(plus, track), minus), 0, decision.source


def position_report(
    run_id: str,
    g: RunGnss,
    track: GisTrack,
    direction: int,
    *,
    cfg: GnssConfig | None = None,
    systems: tuple[str, ...] | None = None,
    sky_mask: SkyMask | None = None,
    sky_mask_name: str = "none",
    track_source: str = "given",
    facing_source: str = "given",
    cab: pd.DataFrame | None = None,
) -> GnssPositionReport:
    """Every epoch of the run on ``track`` (module docstring). ``direction`` +1/−1 is the
    facing given; 0: decided from the fixes' motion (and ``cab``), or unknown and stated so
    (``fieldlogs.gnss.facing``)."""
    cfg = cfg or GnssConfig()
    pc = position_config(cfg, systems)
    tb, direction, decided = _solve(g, track, direction, pc, sky_mask, cab)
    tb = tb.sort_values(["t", "receiver"], kind="stable").reset_index(drop=True)
    sb = g.sbas if pc.use_sbas else None
    return GnssPositionReport(
        run_id,
        track.line_code,
        track.track,
        track_source,
        direction,
        facing_source if decided is None else decided,
        sky_mask_name,
        pc.systems,
        tb[list(COLUMNS)],
        _availability(tb),
        None if sb is None else sbas_summary(sb),
    )


def sbas_summary(sb: SbasCorrections) -> dict[str, Any]:
    """The GEO used longest and its valid messages, the rows dropped by reason, the types not
    decoded, the observation rows by outcome of the last solution (``sbas.clock_orbit``), and
    per GEO its valid messages and the rows it corrected, with the switches between GEOs
    (``sbas.geo_select``)."""
    m = sb.messages
    return {
        "prn": m.geo,
        "messages": m.n_valid,
        "dropped": dict(m.dropped),
        "not_decoded": {str(k): v for k, v in m.not_decoded.items()},
        "rows": dict(sb.counts),
        "geos": {
            str(g): {"messages": gs.messages.n_valid, "rows": sb.used.get(g, 0)} for g, gs in sorted(sb.geos.items())
        },
        "switches": sb.timeline.switches(),
    }
