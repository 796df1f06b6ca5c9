"""Seeded simulated runs through the whole radar processing against the simulator's truth
(statistics only; the timed figures live in bench/bench_radar.py)."""

from __future__ import annotations

import numpy as np
import pytest

from dbtools.network import Network
from fieldlogs.radar.speed import process_if
from schemas.enums import RadarStatus
from tests.fieldlogs.radar.runs import onset_time, radar_of, simulate_radar_run, truth_at

KMH = 3.6


@pytest.mark.slow
def test_accuracy_on_seeded_runs(demo_net: Network) -> None:
    errs, naive, eq2 = [], [], []
    for i, top in ((0, 35.0), (2, 25.0), (3, 20.0)):  # ballast from standstill, slab + vibration, cab R
        streams, meta = simulate_radar_run(i, demo_net, top_kmh=top)
        p = radar_of(meta)
        d = streams["radar_if"]
        c = process_if(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], p).columns
        truth = streams["truth"]
        vt = truth_at(truth, c["t"])
        ok = c["status"] == RadarStatus.OK.value
        sel = ok & (np.abs(vt) > 5 / KMH)
        assert sel.sum() >= 0.95 * (np.abs(vt) > 5 / KMH).sum()
        errs.append((c["speed_mps"][sel] - vt[sel]) * KMH)
        naive.append((c["v_naive_mps"][sel] - vt[sel]) * KMH)
        eq2.append((c["v_eq2_mps"][sel] - vt[sel]) * KMH)
        assert np.all(np.sign(c["speed_mps"][sel]) == np.sign(vt[sel]))
        # the frame holding the motion onset (v > 0.5 km/h), or the next, has a speed
        onset = onset_time(truth)
        k_on = int(np.searchsorted(c["t"] - p.t_epi_s / 2, onset, side="right")) - 1
        assert int(np.argmax(ok)) <= k_on + 1
        # at rest for the whole frame: standstill, never a speed
        edges = np.stack([truth_at(truth, c["t"] + dt) for dt in np.linspace(-p.t_epi_s / 2, p.t_epi_s / 2, 7)])
        rest = np.abs(edges).max(axis=0) < 1e-3
        assert rest.sum() > 20
        assert np.all(c["status"][rest] == RadarStatus.STANDSTILL.value)
    e, n, q = (np.abs(np.concatenate(x)) for x in (errs, naive, eq2))
    assert np.median(e) <= 0.1 and np.quantile(e, 0.95) <= 0.5
    assert np.median(n) > 3 * np.median(e)  # the beam-spread bias eq. 2 removes
    assert np.median(q) > np.median(e)
