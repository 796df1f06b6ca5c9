"""GNSS-only traces matched to a network path (SPEC §8.3, ``trainpos track match``).

A hidden Markov model over candidate tracks with Viterbi decoding [Newson & Krumm 2009]:
:mod:`.geometry` (the network's centrelines as short plane segments), :mod:`.candidates`
(tracks within the search radius of each fix), :mod:`.routes` (route distances through the
topology, navigability respected), :mod:`.hmm` (Viterbi and forward–backward in log space),
:mod:`.match` (the whole calculation), :mod:`.path` and :mod:`.result` (what it returns),
:mod:`.trace` (a run's ``gps`` stream as fixes), :mod:`.output` (GeoJSON).
"""
