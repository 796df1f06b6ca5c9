"""GPS unit: usable fixes, trust filter, map-matching, up/down decisions and crossovers
[S001 §4.2, §7; SPEC §5.4]. Everything per fix is vectorised; only the few moments where
the decision state changes are visited one by one.

* :mod:`.analysis` — usable fixes, map-matching, the run's analysis (and :func:`track_odds`);
* :mod:`.trust` — the trust filter (RMS of the second-to-second change);
* :mod:`.evidence` — the up/down test's statistics over a window of trusted fixes;
* :mod:`.decision` — the decision state machine;
* :mod:`.crossover` — crossover detection.
"""
