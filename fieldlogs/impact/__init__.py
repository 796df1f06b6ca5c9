"""``trainpos db impact``: what a new onboard DB version changes on recorded runs, before ``db release``.

:func:`fieldlogs.impact.runner.impact_runs`: every run below the given roots is replayed by
the replayer (:mod:`fieldlogs.replay`) against both versions in one task
(:func:`fieldlogs.impact.replay.impact_one`: the run is read once, the pipeline runs twice,
both DBs stay loaded in each worker), and the report (:mod:`fieldlogs.impact.report`) compares
per run and per route the balise and feature corrections (count, mean/max
position-correction % [S003 §4.5]), feature refusals and their diagnostics, balise
anomalies, fail-safes, possession alarms (road-rail runs, with a plan) and the largest
margin; :mod:`fieldlogs.impact.page` draws it as HTML.

A run that one version cannot replay is part of the report (its error per version), not
a reason to stop: a new DB that breaks runs is exactly what a maintainer must see. This
package file imports nothing (a light module of the package is imported without the rest).
"""
