"""A run's GNSS streams written as a recorder would: NMEA, UBX or RINEX (``simulate --format``).

The seam for the constellation simulator: every writer takes whatever ``gps``,
``gnss_obs`` and ``gnss_nav`` frames the run holds (``gnss_time_s`` from ``t`` and the
run's ``start_time`` where the gps stream has none). Files go to ``RUN/recorder/``:

* ``nmea``: ``gnss.nmea`` from gps (RMC, VTG, GGA, GSA, GST);
* ``ubx``: ``gnss.ubx`` from gps (NAV-PVT, NAV-HPPOSLLH, NAV-DOP), gnss_obs (RXM-RAWX) and the
  GPS/QZSS (LNAV) and Galileo (I/NAV) rows of gnss_nav (RXM-SFRBX);
* ``rinex``: ``<receiver>.obs`` per receiver (RINEX 3.04) and ``nav.rnx`` — it needs
  gnss_obs, which the simulator does not produce yet (refused with a clear message).

The folder is written atomically and replaced only with ``force``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from dbtools.atomic import atomic_folder
from fieldlogs.io import Run
from fieldlogs.recorders.timebase import iso_to_gps
from schemas.errors import InputError, UsageError

if TYPE_CHECKING:
    from fieldlogs.simulate import Scenario, SimulationSummary

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
    from fieldlogs.recorders import nmea, rinex_nav, rinex_obs, ubx

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
            gj = nav[nav["sat"].str[0].isin(["G", "J", "E"])] if nav is not None else None
            ubx.write_ubx(tmp / "gnss.ubx", gps=gps, obs=obs, nav=gj, gnss=run.raw_json.get("gnss") or None)
            names.append("gnss.ubx")
        else:
            if obs is None or not len(obs):
                raise UsageError(
                    "--format rinex needs raw observations (gnss_obs); the simulator does not produce them yet "
                    "(the constellation simulator will): use --format nmea or ubx"
                )
            for rec, g in obs.groupby("receiver"):
                rinex_obs.write_rinex_obs(g, tmp / f"{rec}.obs")
                names.append(f"{rec}.obs")
            if nav is not None and len(nav):
                rinex_nav.write_rinex_nav(nav, tmp / "nav.rnx", run.raw_json.get("gnss") or {})
                names.append("nav.rnx")
    return [target / n for n in names]


def simulate_with_recorder(
    db_path: Path,
    out: Path,
    fmt: str,
    *,
    scenario: Scenario | None = None,
    seed: int | None = None,
    force: bool = False,
) -> tuple[SimulationSummary, list[Path]]:
    """``simulate`` into a temporary folder, add the recorder files, then rename into ``out``:
    nothing is left behind when the recorder format cannot be written."""
    from fieldlogs.simulate import simulate_to_folder

    if fmt not in EXPORT_FORMATS:
        raise UsageError(f"recorder format '{fmt}' is not one of {', '.join(EXPORT_FORMATS)}")
    with atomic_folder(Path(out), force=force) as tmp:
        summary = simulate_to_folder(db_path, tmp, scenario, seed=seed, fmt="parquet", force=True)
        files = write_recorder_files(tmp, fmt)
    summary.path = Path(out)
    return summary, [Path(out) / RECORDER_FOLDER / f.name for f in files]
