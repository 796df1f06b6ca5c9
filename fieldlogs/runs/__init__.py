"""Field-log run folders (SPEC §4): the only readers and writers of runs.

Layers, each importing only those below it:

* :mod:`.write` — :func:`~fieldlogs.runs.write.write_run` (atomic), ``logs convert``;
* :mod:`.handle` — :class:`~fieldlogs.runs.handle.Run` (:func:`~fieldlogs.runs.handle.read_run`):
  the folder, its findings, its streams read whole or by time window, the CSV spool;
* :mod:`.meta` — ``run.json`` (:class:`~fieldlogs.runs.meta.RunMeta`), its blocks checked by
  :mod:`.blocks` and :mod:`.vehicle` (the vehicle geometry, also that of ``logs import``);
* one typed reader per format, a time window an option of its ``read``:
  :mod:`.csv_reader` (with the spool to Parquet) over :mod:`.parquet_reader`, which reads
  consecutive windows through :mod:`.cursor`; the Parquet file's columns, units and
  statistics in :mod:`.parquet_file`;
* :mod:`.typed` — what they share: the declared-type check of a stream frame, its Arrow form
  with units, :class:`~fieldlogs.runs.typed.TimeWindow`.

CSV numbers are parsed by :mod:`dbtools.typed_csv`, the parser source sets use too.
Recorder formats (NMEA, UBX, RINEX, …) are imported by :mod:`fieldlogs.recorders`.
"""
