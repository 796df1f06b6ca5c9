"""Imported by the fork server of a pipeline replay (the ``preload`` of
:func:`fieldlogs.replay.pool.replay`), never elsewhere: what a pipeline run loads on its
first call is loaded here once, so that every worker forked from the server starts warm
instead of paying it on its first run (bench/NOTES.md, "Performance (issue 21)"): the
compiled matching kernel (:func:`dbtools.gis.match_kernel.warm`) and the modules the
log reader and the pipeline import lazily (Parquet datasets, shapely for GPS areas, the
run.json block checks).
"""

import importlib

from dbtools.gis import match_kernel

#: Modules imported on a run's first use (found with ``sys.modules`` before/after a run).
LAZY_MODULES = (
    "pyarrow.parquet",
    "pyarrow.dataset",
    "shapely",
    "fieldlogs.recorders.blocks",
    "fieldlogs.recorders.vehicle",
)

for _name in LAZY_MODULES:
    importlib.import_module(_name)
match_kernel.warm()
