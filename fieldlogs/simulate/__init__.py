"""Field-log simulator: a seeded, physically consistent run over a DB's line/track.

``simulate_run(network, scenario, seed)`` returns the stream frames (``schemas.logs``
columns) and the ``run.json`` metadata; ``simulate_to_folder`` reads the DB and writes the
run with ``fieldlogs.runs.write.write_run`` (both in :mod:`.simulator`; this package file imports
nothing). The pieces, one concern per module:

* ``scenario`` — knobs (TOML, documented in ``fieldlogs/simulate/scenarios/default.toml``);
* ``track`` — GIS grid → C2 splines: heading, curvature, gradient, cant, arc length;
* ``running`` — moves, stops, curve limits, jerk-limited speed profile at 100 Hz;
* ``kinematics`` — body attitude, specific force and rates (SPEC §4.1 frame);
* ``slip`` — slip/slide episodes; ``sensors`` — IMU, tacho, GPS, radar, truth;
* ``radar`` — raw IF samples of the 2-frequency CW radar (``sensors.radar_if``);
* ``events`` — balise telegrams and cab events;
* raw GNSS (``[gnss_raw]``, off by default) — :mod:`fieldlogs.simulate.gnss.trainsim`;
* a run routed over a network (``[network]``, ``scenario_net``): ``netroute`` the tracks of the
  route, ``netgeom`` its geometry (one route coordinate through the centrelines, true turnout
  arcs, no cant and a speed cap on turnouts, truth track_id/pos_m), ``netsim`` what the route
  changes in the run; ``samples_net`` the sample runs over the sample network's switches,
  ``network_runs`` many seeded runs through a network's switches for statistics.

Everything random comes from ``np.random.default_rng(seed)`` (one child generator per
concern, so switching a sensor off does not change the others).
"""
