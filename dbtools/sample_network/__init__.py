"""The bundled sample network: the JR East Kawagoe Line, Kawagoe–Komagawa (line 0420).

A railway alignment fitted to the line's real (coarse) geometry from ``nagix/mini-tokyo-3d``
(MIT licence, © nagix; station data originally from ODPT), with a GIS grid for two tracks,
balises at its six real stations and feature points at its real curves. See ``SOURCE.md``
for the source, licence and method; regenerate with
``python -m fieldlogs.simulate.networks.sample_build``.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent


def sample_source_dir() -> Path:
    """The packaged source set (gis, balises, feature_points, lines): ``db build`` reads it."""
    return PACKAGE_DIR / "sources"


def sample_network_source_dir() -> Path:
    """The same line with a four-track station, a crossover pair and a junction (tracks,
    connections, switches, track_points, ETCS-style balise groups, branch line 0421;
    :mod:`fieldlogs.simulate.networks.sample_junctions`): what the demo and the ``sim-net-*`` sample runs use."""
    return PACKAGE_DIR / "network_sources"


def sample_survey_dir() -> Path:
    """The packaged survey (centrelines.csv, kmposts.csv) that ``gis grid`` turns into gis.csv."""
    return PACKAGE_DIR / "survey"


def sample_raw_dir() -> Path:
    """The copied mini-tokyo-3d rows (kawagoe_line.csv, kawagoe_stations.csv)."""
    return PACKAGE_DIR / "raw"
