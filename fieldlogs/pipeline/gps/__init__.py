"""GPS unit: usable fixes, trust filter, map-matching, up/down decisions and crossovers
[S001 §4.2, §7; SPEC §5.4]. Everything per fix is vectorised; only the few moments where
the decision state changes are visited one by one.

* :mod:`.analysis` — usable fixes, map-matching, the run's analysis (and :func:`track_odds`);
* :mod:`.trust` — the trust filter (RMS of the second-to-second change);
* :mod:`.evidence` — the up/down test's statistics over a window of trusted fixes;
* :mod:`.decision` — the decision state machine;
* :mod:`.crossover` — crossover detection.
"""

from __future__ import annotations

from fieldlogs.pipeline.gps.analysis import DECIDED_COLUMNS, FIX_COLUMNS, TrackOdds, analyse_gps, track_odds
from fieldlogs.pipeline.gps.evidence import mean_variance_factor
from fieldlogs.pipeline.gps.trust import trust_filter

__all__ = [
    "DECIDED_COLUMNS",
    "FIX_COLUMNS",
    "TrackOdds",
    "analyse_gps",
    "mean_variance_factor",
    "track_odds",
    "trust_filter",
]
