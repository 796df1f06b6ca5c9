"""A run's GNSS streams written as a recorder would: NMEA, UBX or RINEX (``simulate --format``).

Every writer takes whatever ``gps``, ``gnss_obs`` and ``gnss_nav`` frames the run holds
(``gnss_time_s`` from ``t`` and the run's ``start_time`` where the gps stream has none). Files go to ``RUN/recorder/``:

* ``nmea``: ``gnss.nmea`` from gps (RMC, VTG, GGA, GSA, GST);
* ``ubx``: ``gnss.ubx`` from gps (NAV-PVT, NAV-HPPOSLLH, NAV-DOP) — with the run's gnss_obs
  (RXM-RAWX) and the GPS/QZSS (LNAV) and Galileo (I/NAV) rows of gnss_nav (RXM-SFRBX) when it
  has one receiver; with several receivers each gets its own ``<receiver>.ubx`` (RXM-RAWX,
  RXM-SFRBX and the ionosphere page), as each receiver writes its own file; the run's
  ``gnss_sbas`` messages go as RXM-SFRBX frames of gnssId 1 into the file with the
  observations (the first receiver's of several: one import source per stream), since the
  reader times an SBAS frame by the RXM-RAWX epoch after it;
* ``rinex``: ``<receiver>.obs`` per receiver (RINEX 3.04) and ``nav.rnx`` — it needs
  gnss_obs (``trainpos simulate`` switches ``[gnss_raw]`` on for it).

With a run.json ``vehicle`` block, ``vehicle.toml`` (the ``logs import --vehicle`` file) is
written beside them, so that the recorder files import back into a run.

The folder is written atomically and replaced only with ``force``. A simulated run with its
recorder files in one step: :func:`fieldlogs.simulate.recorder.simulate_with_recorder`.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from dbtools.atomic import atomic_folder
from fieldlogs.recorders.timebase import iso_to_gps
from fieldlogs.runs.handle import Run
from schemas.errors import InputError, UsageError

RECORDER_FOLDER = "recorder"
EXPORT_FORMATS = ("nmea", "ubx", "rinex")


def _gps(run: Run) -> pd.DataFrame | None:
    gps = run.stream("gps")
    if gps is None or not len(gps):
        return None
    gps = gps.copy()
    if "gnss_time_s" not in gps.columns or gps["gnss_time_s"].isna().any():
        start = run.field("start_time")
        if start is None:
            raise InputError("run.json has no usable start_time: the fixes have no absolute time", path=run.folder)
        gps["gnss_time_s"] = iso_to_gps(str(start)) + gps["t"].to_numpy(dtype=float)
    return gps


def write_recorder_files(run_folder: Path, fmt: str, *, force: bool = False) -> list[Path]:
    """Write the run's GNSS part in ``fmt`` into ``RUN/recorder/``; the files written."""
    from fieldlogs.recorders import nmea, rinex_nav, rinex_obs

    if fmt not in EXPORT_FORMATS:
        raise UsageError(f"recorder format '{fmt}' is not one of {', '.join(EXPORT_FORMATS)}")
    run = Run(Path(run_folder))
    gps, obs, nav = _gps(run), run.stream("gnss_obs"), run.stream("gnss_nav")
    target = run.folder / RECORDER_FOLDER
    names: list[str] = []
    with atomic_folder(target, force=force) as tmp:
        if fmt == "nmea":
            if gps is None:
                raise UsageError("--format nmea needs a gps stream")
            nmea.write_nmea(gps, tmp / "gnss.nmea")
            names.append("gnss.nmea")
        elif fmt == "ubx":
            names += _write_ubx(run, tmp, gps, obs, nav)
        else:
            if obs is None or not len(obs):
                raise UsageError(
                    "--format rinex needs raw observations (gnss_obs): simulate with [gnss_raw] enabled = true "
                    "(trainpos simulate --format rinex does), or use --format nmea or ubx"
                )
            for rec, g in obs.groupby("receiver"):
                rinex_obs.write_rinex_obs(g, tmp / f"{rec}.obs")
                names.append(f"{rec}.obs")
            if nav is not None and len(nav):
                rinex_nav.write_rinex_nav(nav, tmp / "nav.rnx", run.raw_json.get("gnss") or {})
                names.append("nav.rnx")
        vehicle = run.raw_json.get("vehicle")
        if isinstance(vehicle, dict):
            (tmp / "vehicle.toml").write_text(vehicle_toml(vehicle), encoding="utf-8")
            names.append("vehicle.toml")
    return [target / n for n in names]


def _write_ubx(
    run: Run, tmp: Path, gps: pd.DataFrame | None, obs: pd.DataFrame | None, nav: pd.DataFrame | None
) -> list[str]:
    """``gnss.ubx`` (and one ``<receiver>.ubx`` per receiver of a multi-receiver run)."""
    from fieldlogs.recorders import ubx

    gj = nav[nav["sat"].str[0].isin(["G", "J", "E"])] if nav is not None else None
    block = run.raw_json.get("gnss") or None
    receivers = sorted(obs["receiver"].astype(str).unique()) if obs is not None and len(obs) else []
    sbas = run.stream("gnss_sbas") if receivers else None
    if len(receivers) <= 1:
        ubx.write_ubx(tmp / "gnss.ubx", gps=gps, obs=obs, nav=gj, gnss=block, sbas=sbas)
        return ["gnss.ubx"]
    assert obs is not None
    names = []
    if gps is not None:
        ubx.write_ubx(tmp / "gnss.ubx", gps=gps)
        names.append("gnss.ubx")
    for k, rec in enumerate(receivers):
        sb = sbas if k == 0 else None
        ubx.write_ubx(tmp / f"{rec}.ubx", obs=obs[obs["receiver"] == rec], nav=gj, gnss=block, sbas=sb)
        names.append(f"{rec}.ubx")
    return names


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def vehicle_toml(vehicle: dict[str, object]) -> str:
    """A run.json ``vehicle`` block as the ``logs import --vehicle`` TOML (``schemas.vehicle``)."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in vehicle.items() if not isinstance(v, dict | list)]
    for k, v in vehicle.items():
        if isinstance(v, dict):
            lines += ["", f"[{k}]", *(f"{kk} = {_toml_value(vv)}" for kk, vv in v.items())]
        elif isinstance(v, list):
            for item in v:
                if isinstance(item, dict):
                    lines += ["", f"[[{k}]]", *(f"{kk} = {_toml_value(vv)}" for kk, vv in item.items())]
    return "\n".join(lines) + "\n"
