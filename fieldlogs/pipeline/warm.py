"""Imported before the workers of a pipeline replay start (the ``preload`` of
:func:`fieldlogs.replay.pool.replay`), never elsewhere: what a pipeline run loads on its
first call is loaded here once, so that every worker starts warm instead of paying it on
its first run (bench/NOTES.md, "Performance (issue 21)"): the modules the log reader and
the pipeline import lazily (Parquet datasets, shapely for GPS areas, the run.json block
checks) and, in a fork server only, the compiled matching kernel
(:func:`dbtools.gis.match_kernel.warm`). A coordinator that forks its workers itself does
not load the kernel (0.5 s of CPU), nor import its module (a match uses the kernel once
its module is imported, :meth:`dbtools.gis.matching.TrackIndex.match_xy`): runs of up to
``NUMPY_MAX_FIXES`` fixes never use it, and a worker loads it on its first longer run, as
one process does.
"""

import importlib
import sys

#: Modules imported on a run's first use (found with ``sys.modules`` before/after a run).
LAZY_MODULES = (
    "pyarrow.parquet",
    "pyarrow.dataset",
    "shapely",
    "fieldlogs.runs.blocks",
    "fieldlogs.runs.vehicle",
    "fieldlogs.pipeline.windows",
    "numpy.fft",
)

for _name in LAZY_MODULES:
    importlib.import_module(_name)
if "fieldlogs.replay._server" in sys.modules:  # imported by a fork server only
    # not imported elsewhere: a match takes the kernel whenever its module is loaded
    from dbtools.gis import match_kernel

    match_kernel.warm()
