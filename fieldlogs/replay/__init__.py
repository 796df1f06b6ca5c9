"""One parallel replayer of recorded runs, shared by ``audit``, ``gis verify`` and ``possession check``.

A *replay* calls a per-run worker function ``worker(run_path, *args)`` on many run folders
and yields one :class:`~fieldlogs.replay.pool.Outcome` per run — its value, or the one-line
error message of a run that failed (an error never stops the fleet):

* :mod:`fieldlogs.replay.discovery` — the run folders (holding ``run.json``) under roots;
* :mod:`fieldlogs.replay.network` — the onboard DB as a picklable :class:`DbRef` (path and
  content hash) and its per-process cache: each worker process loads a DB once;
* :mod:`fieldlogs.replay.pool` — :func:`replay`: in this process, in a local process pool
  (fork server) or on a Dask cluster, through the same worker call; ordered or
  as-completed results, a progress callback, and cancellation (closing the iterator, e.g.
  on Ctrl-C) that leaves no worker, fork-server or resource-tracker process behind.

This package imports nothing at start-up: the fork server imports
:mod:`fieldlogs.replay._server` first, before anything heavy.
"""
