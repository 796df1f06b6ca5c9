"""Networks the simulator and the tests run on: synthetic lines and the bundled sample's builder.

* ``alignment`` — the "true" geometry: straights, clothoids and circular arcs;
* ``synthetic`` — network tables (GIS grid, balises, feature points, lines) of a
  ``LineSpec``: the demo line, random alignments;
* ``survey`` — the survey (centreline vertices, km posts) of a ``LineSpec``;
* ``topology`` — station layouts (tracks, connections, switches) of a national-scale network;
* ``turnout`` — turnout geometry: the reverse curves of loops and crossovers, exact paths;
* ``sample_fit`` and ``sample_build`` — the bundled sample network (``dbtools/sample_network``,
  the data ``trainpos demo`` builds) fitted to the real Kawagoe Line and written:
  ``python -m fieldlogs.simulate.networks.sample_build``; ``sample_junctions`` — its station,
  crossover pair and junction (``dbtools/sample_network/network_sources``).
"""
