"""The aids of the positioning engine, and the registry that builds them for a run.

Each entry of :data:`~.registry.POSITION_AIDS` / :data:`~.registry.SPEED_AIDS`
(:mod:`.registry`) is a factory that looks at the run's context (streams present, vehicle,
network, configuration, the vectorised products) and returns its aid, or None when the
run cannot feed it. A new sensor is a new module here and one line in the registry; the
engine does not change. This package file imports nothing (a light module of the package
is imported without the rest).
"""
