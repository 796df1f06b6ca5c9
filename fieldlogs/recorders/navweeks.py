"""Navigation records put on the observations' GPS weeks (the 10-bit week rollover).

A GPS week is broadcast in 10 bits (IS-GPS-200 §20.3.3.3.1.1: modulo 1024, 19.6 years);
RINEX 3.05 Table A6 asks for the continuous week. Two faults reach ``gnss_nav``:

* ``week`` written modulo 1024 while the record epoch ``toc`` (a calendar date) is right —
  resolved by the navigation reader against ``toc`` (``rinex_nav._resolve_weeks``);
* a receiver with the rollover bug dates the whole file 1024·k weeks early (both ``toc`` and
  ``week``): resolved here, at import, against the observations of the same import — the
  rollover nearest them, ``k = round(Δ / 1024 weeks)`` for the offset Δ of the records'
  median ``toc`` from the observations' midpoint, when Δ lies within ``ROLLOVER_SLACK_WEEKS``
  of 1024·k. Navigation records otherwise more than ``ROLLOVER_SLACK_WEEKS`` from the
  observations are named (a warning): no ephemeris will match them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fieldlogs.recorders.common import Decoded
from schemas.enums import Severity
from schemas.findings import Finding

WEEK_S = 604_800.0
#: Weeks of one 10-bit rollover of the GPS week (IS-GPS-200 §20.3.3.3.1.1).
WEEK_ROLLOVER = 1024
#: How far (weeks) from a rollover multiple, or from the observations, records may lie.
ROLLOVER_SLACK_WEEKS = 2.0


def _obs_span(decoded: Sequence[Decoded]) -> tuple[float, float] | None:
    times = [
        f["gnss_time_s"].to_numpy(dtype=float)
        for d in decoded
        for name, f in d.frames.items()
        if name != "gnss_nav" and "gnss_time_s" in f.columns and len(f)
    ]
    t = np.concatenate(times) if times else np.zeros(0)
    t = t[np.isfinite(t)]
    return (float(t.min()), float(t.max())) if t.size else None


def nav_onto_observations(decoded: Sequence[Decoded]) -> list[Finding]:
    """Shift each source's navigation records dated a whole number of rollovers away from the
    observations onto them (in place, with a note in its provenance); name the ones that lie
    elsewhere (module docstring)."""
    span = _obs_span(decoded)
    found: list[Finding] = []
    if span is None:
        return found
    mid = 0.5 * (span[0] + span[1])
    for d in decoded:
        nav = d.frames.get("gnss_nav")
        if nav is None or not len(nav) or not nav["toc_gps_s"].notna().any():
            continue
        toc = nav["toc_gps_s"].to_numpy(dtype=float)
        weeks = (float(np.nanmedian(toc)) - mid) / WEEK_S
        k = round(weeks / WEEK_ROLLOVER)
        if k != 0 and abs(weeks - WEEK_ROLLOVER * k) <= ROLLOVER_SLACK_WEEKS:
            nav = nav.copy()
            nav["toc_gps_s"] = toc - WEEK_ROLLOVER * k * WEEK_S
            nav["week"] = nav["week"] - WEEK_ROLLOVER * k
            d.frames["gnss_nav"] = nav
            d.notes.append(
                f"navigation records dated {WEEK_ROLLOVER * k:+d} weeks from the observations (the 10-bit GPS week "
                f"rollover, IS-GPS-200 §20.3.3.3.1.1): {len(nav)} record(s) moved to the rollover nearest them"
            )
        elif abs(weeks) > ROLLOVER_SLACK_WEEKS:
            found.append(
                Finding(
                    "import.nav_epochs",
                    Severity.WARNING,
                    "gnss_nav",
                    f"the navigation records lie {weeks * 7:+.0f} days from the observations: no ephemeris will "
                    "match them (a navigation file of another day?)",
                    file=d.file,
                    column="toc_gps_s",
                    value=weeks * 7,
                )
            )
    return found
