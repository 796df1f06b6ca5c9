"""``trainpos survey``: the onboard DB checked against what the fleet measured (issue 19).

S003 §5.5 explains a line's higher position-correction percentage by balise positions
that differ from the DB; S003 §6 ③ wants balises that no longer answer found from the
trains' own logs; S000 §4.3.2 builds the feature-point DB from measured curvature traces;
and on a fleet the correction percentage is mostly the wheels' wear. One replay of every
run feeds all of them:

* :mod:`~fieldlogs.survey.extract` — per run (the replayer's worker): the pipeline's
  positions in segments, every telegram located and identified, the passes over DB
  balises, the curvature samples near curves, and the GIS evidence of ``gis verify``;
* :mod:`~fieldlogs.survey.dbindex` — the DB's balises arranged for identification;
* :mod:`~fieldlogs.survey.trajectory` — reads as chains, travel → km through them;
* :mod:`~fieldlogs.survey.balises` — residuals from both sides, the adjustment, wheel scales;
* :mod:`~fieldlogs.survey.inspection` — balise statuses, missed passes, candidates;
* :mod:`~fieldlogs.survey.curvature`, :mod:`~fieldlogs.survey.features`,
  :mod:`~fieldlogs.survey.featurecompare` — curvature profiles, curves by the pipeline's
  lower-limit rule, the comparison with the DB's feature points;
* :mod:`~fieldlogs.survey.wheels` — diameters per run and vehicle, alert;
* :mod:`~fieldlogs.survey.propose` — the corrected source set and its evidence;
* :mod:`~fieldlogs.survey.runner` — discover, replay, aggregate (with ``gis verify``);
* :mod:`~fieldlogs.survey.result`, :mod:`~fieldlogs.survey.page` — the report, its JSON
  and its HTML page; :mod:`~fieldlogs.survey.config` — the ``[survey]`` settings.

Nothing here changes the pipeline: everything is read from its result.
"""
