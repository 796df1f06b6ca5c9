"""Experiment harnesses: positioning code run on simulated data, for the benchmarks and tests.

A harness joins the two sides the product keeps apart — the simulator (``fieldlogs.simulate``)
that writes the truth and the positioning code under test — so it lives in neither: nothing
in the product imports it (``tests/test_simulator_apart.py``).

* ``gnss`` — seeded cases of the track-constrained GNSS positioning [S002] and their statistics.
"""
