"""A run's inputs of GNSS positioning: ``gnss_obs``, ``gnss_nav``, the navigation header
(run.json ``gnss``) and the antennas on the vehicle (run.json ``vehicle``).

* Ionosphere parameters: ``klobuchar_alpha``/``klobuchar_beta`` (GPS, and QZSS and Galileo
  without their own), ``qzss_klobuchar_*`` (QZSS), ``nequick_ai`` (Galileo's effective
  ionisation, :mod:`fieldlogs.gnss.atmosphere`); without any the ionosphere is not modelled
  (import the navigation file with the observations to get them).
* Antennas: every ``vehicle.antennas[]`` entry gives the receiver of its ``gnss_obs`` rows
  and its place on the vehicle: x forward toward the F end (``along``), y left (``lateral``),
  z above the rail top (``height``), all from the vehicle's reference point — the point whose
  km the pipeline reports. Which way along the track x points depends on which end of the
  vehicle faces increasing km (the solver's ``direction``, the sign of km per metre of travel
  toward the F end).
* SBAS/MSAS: the run's ``gnss_sbas`` messages (``fieldlogs.gnss.sbas``), decoded once.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from fieldlogs.gnss.observables import epoch_keys
from fieldlogs.gnss.track import Antenna
from fieldlogs.runs.handle import Run
from schemas.errors import EXIT_FINDINGS, TrainposError

if TYPE_CHECKING:
    from fieldlogs.gnss.sbas import SbasCorrections

#: run.json ``gnss`` keys → the ionosphere parameter names of the GNSS core.
IONO_KEYS = {
    "klobuchar_alpha": "gps_alpha",
    "klobuchar_beta": "gps_beta",
    "qzss_klobuchar_alpha": "qzss_alpha",
    "qzss_klobuchar_beta": "qzss_beta",
    "nequick_ai": "gal_ai",
}


class GnssInputError(TrainposError):
    """A run whose GNSS part cannot be positioned (no navigation data, a receiver without antenna)."""

    exit_code = EXIT_FINDINGS

    def __init__(self, message: str, *, reason: str, path: str | None = None) -> None:
        super().__init__(message, path=path)
        self.reason = reason


@dataclass(frozen=True)
class RunGnss:
    """The inputs of one run (module docstring)."""

    obs: pd.DataFrame
    nav: pd.DataFrame
    iono: dict[str, tuple[float, ...]]
    antennas: dict[str, Antenna]
    """Receiver → antenna, for the receivers that have observations."""
    times: np.ndarray
    """Distinct run times t of the receivers' epochs (ascending)."""
    keys: np.ndarray
    """Common epoch of each of ``times`` (``observables.epoch_keys``: receivers' epochs within
    20 ms are one epoch)."""
    sbas_frame: pd.DataFrame | None = None
    """The run's ``gnss_sbas`` rows (None: no stream)."""

    @cached_property
    def sbas(self) -> SbasCorrections | None:
        """The decoded SBAS messages (None without a stream or without a valid message)."""
        if self.sbas_frame is None or not len(self.sbas_frame):
            return None
        from fieldlogs.gnss.sbas import SbasCorrections  # the decoder, only for runs with a stream

        dec = SbasCorrections.from_stream(self.sbas_frame)
        return None if dec.empty else dec

    @property
    def epoch_times(self) -> np.ndarray:
        """Run time of every common epoch (its earliest receiver epoch), ascending."""
        _, first = np.unique(self.keys, return_index=True)
        return np.asarray(self.times[first], dtype=float)

    def epoch_of(self, t: np.ndarray) -> np.ndarray:
        """Common epoch of run times ``t`` that are receiver epochs of this run."""
        i = np.clip(np.searchsorted(self.times, np.asarray(t, dtype=float)), 0, self.times.size - 1)
        return np.asarray(self.keys[i], dtype=np.int64)


def iono_params(block: Mapping[str, Any] | None) -> dict[str, tuple[float, ...]]:
    """Ionosphere parameters of the core from a run.json ``gnss`` block (module docstring)."""
    out: dict[str, tuple[float, ...]] = {}
    for key, name in IONO_KEYS.items():
        v = (block or {}).get(key)
        if isinstance(v, list | tuple) and v and all(isinstance(x, int | float) for x in v):
            out[name] = tuple(float(x) for x in v)
    return out


def antennas_of(vehicle: Mapping[str, Any] | None) -> dict[str, Antenna]:
    """Receiver → antenna of a vehicle block (entries without a receiver or coordinates skipped:
    ``logs check`` reports them)."""
    out: dict[str, Antenna] = {}
    for a in (vehicle or {}).get("antennas") or []:
        if not isinstance(a, dict) or not isinstance(a.get("receiver"), str):
            continue
        try:
            out[a["receiver"]] = Antenna(float(a["x_m"]), float(a["y_m"]), float(a["z_m"]))
        except (KeyError, TypeError, ValueError):
            continue
    return out


#: An ephemeris further than this from every observation epoch serves none [s] (the longest
#: fit interval of a broadcast ephemeris is hours; a day is far beyond any).
NAV_REACH_S = 86_400.0


def _check_nav_epochs(obs: pd.DataFrame, nav: pd.DataFrame, folder: str) -> None:
    """Refuse navigation data none of whose reference epochs (Toe = week·604800 + Toe for
    Keplerian records, toc for GLONASS) lies within ``NAV_REACH_S`` of the observations: every
    epoch would read as too few satellites. The usual cause is a 10-bit week (modulo 1024,
    IS-GPS-200 §20.3.3.3.1.1) left unresolved, which is named with the weeks found."""
    if "gnss_time_s" not in obs.columns or not {"week", "Toe", "toc_gps_s"} <= set(nav.columns):
        return
    g = obs["gnss_time_s"].to_numpy(dtype=float, na_value=np.nan)
    g = g[np.isfinite(g)]
    toe = nav["week"].to_numpy(dtype=float, na_value=np.nan) * 604_800.0 + nav["Toe"].to_numpy(
        dtype=float, na_value=np.nan
    )
    ref = np.where(np.isfinite(toe), toe, nav["toc_gps_s"].to_numpy(dtype=float, na_value=np.nan))
    ref = ref[np.isfinite(ref)]
    if not g.size or not ref.size:
        return
    if bool(((ref >= g.min() - NAV_REACH_S) & (ref <= g.max() + NAV_REACH_S)).any()):
        return
    weeks = np.floor(ref / 604_800.0)
    raise GnssInputError(
        f"no ephemeris of gnss_nav lies within a day of the observations (GPS week {int(g.min() // 604_800)}; "
        f"navigation weeks {int(weeks.min())}–{int(weeks.max())}): a 10-bit GPS week (modulo 1024) not resolved, "
        "or a navigation file of another day — re-import with logs import, see logs check",
        reason="nav_epochs",
        path=folder,
    )


def run_gnss(run: Run) -> RunGnss | None:
    """The run's GNSS inputs, or None when it has no ``gnss_obs`` rows.

    Raises :class:`GnssInputError` when observations exist but cannot be positioned: no
    ``gnss_nav``, none of its ephemerides near the observations (``_check_nav_epochs``), or
    a receiver without an antenna in the vehicle block.
    """
    obs = run.stream("gnss_obs")
    if obs is None or not len(obs):
        return None
    nav = run.stream("gnss_nav")
    if nav is None or not len(nav):
        raise GnssInputError(
            "the run has gnss_obs but no gnss_nav (ephemerides)", reason="no_nav", path=str(run.folder)
        )
    _check_nav_epochs(obs, nav, str(run.folder))
    meta = run.meta
    antennas = antennas_of(meta.vehicle if meta is not None else None)
    observed = {str(r) for r in pd.unique(obs["receiver"].to_numpy(dtype=object))}
    missing = sorted(observed - set(antennas))
    if missing:
        raise GnssInputError(
            f"run.json vehicle block has no antenna for receiver(s) {', '.join(missing)}",
            reason="no_antenna",
            path=str(run.folder / "run.json"),
        )
    antennas = {r: a for r, a in antennas.items() if r in observed}
    t = np.unique(obs["t"].to_numpy(dtype=float))
    iono = iono_params(meta.gnss if meta is not None else None)
    return RunGnss(obs, nav, iono, antennas, t, epoch_keys(t), run.stream("gnss_sbas"))
