"""The GNSS part of the simulator: the world as a receiver would see it [S002].

* ``constellation`` — GPS/Galileo/QZSS broadcast ephemerides generated from mean orbits;
* ``observations`` — pseudoranges, carrier, Doppler and C/N0 of antennas on a moving vehicle
  (ionosphere, troposphere, orbit/clock errors, multipath, NLOS, receiver clocks);
* ``scenario`` — a synthetic 3-D test track, runs with stops and the corridor around it;
* ``trainsim`` — the same driven by the train simulator's truth (``[gnss_raw]``);
* ``sbas_encode`` — SBAS L1 messages (RTCA DO-229) encoded from the standard's tables,
  apart from the decoder so that each checks the other; ``sbas_stream`` — the ``gnss_sbas``
  stream consistent with a simulated run.

The physics shared with the receiver — ICD constants, geodesy, the broadcast-ephemeris
algorithm, the Klobuchar and Saastamoinen models, the DO-229 tables, the 3-D track polyline —
is imported from ``fieldlogs.gnss``; its solvers (observables, pre-checks, the constrained
and unconstrained least squares, FDE, SBAS corrections) are not (``tests/test_simulator_apart.py``).
"""
