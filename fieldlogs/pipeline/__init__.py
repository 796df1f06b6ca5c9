"""The onboard positioning pipeline of SPEC §5 on a recorded run.

:func:`fieldlogs.pipeline.run.run_pipeline` replays a run (its data flow is in
:mod:`fieldlogs.pipeline.run`); the settings are :mod:`fieldlogs.pipeline.config`. This
package file imports nothing, so that a light module of the package (the settings) can be
imported without the whole pipeline (``trainpos --help`` needs no numpy).
"""
