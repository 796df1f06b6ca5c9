"""GNSS core of the track-constrained positioning [S002] (SPEC §5.6).

Modules, one concern each:

* ``constants`` — ICD constants per system, signals, the frame columns;
* ``ephemeris`` — broadcast ephemeris selection, satellite position/velocity/clock, Sagnac;
* ``geodesy`` — ECEF ↔ geodetic, ENU, azimuth/elevation;
* ``atmosphere`` — Klobuchar, the Galileo effective-ionisation model, Saastamoinen;
* ``corrections`` — the D-GPS corrections seam and the per-row corrections form;
* ``sbas`` — SBAS/MSAS L1 messages (RTCA DO-229): stream screening, decoding, fast/long-term
  corrections with σ_flt, the ionospheric grid;
* ``sbas_tables`` — DO-229's look-up tables and IGP bands (the decoder's and the simulator's);
* ``observables`` — gnss_obs + gnss_nav frames → corrected pseudorange arrays per epoch;
* ``errormodel`` — pseudorange σ from elevation and C/N0;
* ``lsq`` — the unconstrained (x, y, z, clock [, inter-system bias]) least squares, DOPs;
* ``track`` — the 3-D track polyline and the antennas on the vehicle;
* ``constrained`` — the track-constrained (s, clock per receiver) Gauss–Newton with FDE;
  ``reference`` — the same, epoch by epoch (yardstick and check); ``linalg`` — batched solves;
* ``coasting`` — receiver clock prediction for epochs the satellites alone cannot carry;
* ``prechecks`` — the paper's per-epoch input checks; ``skymask`` — blocked sky;
* ``position`` — one run: pre-checks, geometry, constrained and unconstrained solutions;
* ``gis`` — the DB's GIS grid of a line/track as the 3-D polyline (heights required,
  ellipsoidal) with km; ``runinputs`` — a run's observations, ephemerides, ionosphere
  parameters and antennas; ``ontrack`` — a run solved on a track, the best receiver per epoch,
  the evidence between two tracks; ``report`` — ``trainpos gnss position``; ``config`` — the
  ``[gnss]`` section.

Nothing here imports the pipeline: its GNSS aid (``fieldlogs.pipeline.aids.gnss``) uses
``ontrack``. Nor the simulator: the simulated constellation, observations, SBAS stream and
test track are in ``fieldlogs.simulate.gnss``, the seeded experiments in
``fieldlogs.experiments.gnss``.
"""
