"""Never a determined cycle on a wrong track: random routes over the hand-made networks
(tests/data/networks), odometry with a scale error inside the margin's distance share, GPS
fixes with a bias and noise inside the GPS model and turnout yaw with gyro noise inside the
IMU model. The truth is walked along the topology here, choosing a random branch at each
facing switch."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import Network
from dbtools.topology import BEGIN, END
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gps import TrackGpsAid
from fieldlogs.pipeline.aids.track_imu import TrackImuAid, turnouts
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import TrackLines, track_lines
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, Start, net

DT = 0.1
_R = 6_371_000.0


@dataclass
class Truth:
    track: list[str]
    pos: np.ndarray
    s: np.ndarray
    d: np.ndarray
    wz: np.ndarray


def start_on_line(name: str, start: int) -> tuple[Network, TrackLines, str, float]:
    """The test network ``name``, its track lines, and a start drawn from ``start``: one of
    the tracks along a line, at a place ≥ 20 m from both its ends."""
    n = net(name)
    lines = track_lines(n)
    on_line = [t for t in sorted(lines.lines) if lines[t].line_code and lines[t].metric is not None]
    tid = on_line[start % len(on_line)]
    pos0 = 20.0 + (start % 97) / 97.0 * max(lines[tid].length_m - 40.0, 1.0)
    return n, lines, tid, pos0


def walk(network: Network, lines: TrackLines, tid: str, pos: float, kp: int, v: np.ndarray, branch: list[int]) -> Truth:
    """The true track and pos per cycle for signed speeds ``v``; at a facing switch the exit
    ``branch[k] % n`` of the k-th one; the train stops at a dead end; yaw rate on turnout leads."""
    sw = {str(r["switch_id"]): r for r in network.switches.to_dict("records")}
    tracks, poss, s_out, d_out, wz = [], [], [], [], np.zeros(v.size)
    s = d = 0.0
    nfacing = 0
    turn: tuple[float, float] | None = None  # (rate, travel left on the lead)
    for i, vi in enumerate(v):
        tracks.append(tid)
        poss.append(pos)
        s_out.append(s)
        d_out.append(d)
        step = vi * DT
        if turn is not None:
            wz[i] = turn[0]
            turn = (turn[0], turn[1] - abs(step)) if turn[1] - abs(step) > 0 else None
        new = pos + kp * step
        tl = lines[tid]
        end = END if new > tl.length_m else BEGIN if new < 0 else None
        if end is None:
            pos, s, d = new, s + step, d + abs(step)
            continue
        exits = lines.topo.exits.get((tid, end), [])
        if not exits:
            v[i + 1 :] = 0.0  # a dead end: stop here
            continue
        ex = exits[branch[nfacing % len(branch)] % len(exits)] if len(exits) > 1 else exits[0]
        if len(exits) > 1:
            nfacing += 1
            row = sw.get(ex.switch_id or "")
            if row is not None and row["type"] == "point" and row["diverging_side"] in ("left", "right"):
                left = row["diverging_side"] == "left"  # the diverging branch turns left: ωz > 0
                if ex.track_id == row["b1_track" if left else "b2_track"]:
                    r, a = float(row["diverging_radius_m"]), math.atan(1.0 / float(row["switch_number"]))
                    turn = (abs(vi) / r * (1.0 if left else -1.0), r * a)
        out = new - tl.length_m if end == END else -new
        motion = kp if end == END else -kp
        entry = 0.0 if ex.end == BEGIN else lines[ex.track_id].length_m
        tid, pos, kp = ex.track_id, entry + ex.direction * out, ex.direction * motion
        s, d = s + step, d + abs(step)
    return Truth(tracks, np.array(poss), np.array(s_out), np.array(d_out), wz)


def latlon(lines: TrackLines, tid: str, pos: float) -> tuple[float, float]:
    tl = lines[tid]
    x, y, _, _ = tl.point(pos)
    lat0, lon0 = tl.origin
    k = math.pi / 180.0 * _R
    return lat0 + y / k, lon0 + x / (k * math.cos(math.radians(lat0)))


@settings(max_examples=60, deadline=None)
@given(
    name=st.sampled_from(["junction", "crossover", "station4", "double_slip"]),
    start=st.integers(0, 10_000),
    kp=st.sampled_from([1, -1]),
    speed=st.floats(4.0, 20.0),
    reverse_at=st.floats(0.3, 1.5),
    scale=st.floats(-0.015, 0.015),
    branch=st.lists(st.integers(0, 1), min_size=1, max_size=4),
    bias=st.floats(-1.5, 1.5),
    seed=st.integers(0, 2**16),
    gps=st.booleans(),
)
def test_no_determined_cycle_on_a_wrong_track(
    name: str,
    start: int,
    kp: int,
    speed: float,
    reverse_at: float,
    scale: float,
    branch: list[int],
    bias: float,
    seed: int,
    gps: bool,
) -> None:
    n, lines, tid, pos0 = start_on_line(name, start)
    tl = lines[tid]
    steps = round(600.0 / speed / DT)  # 600 m, then back for reverse_at × that
    v = np.concatenate([np.full(steps, speed), np.full(int(steps * reverse_at), -speed)])
    truth = walk(n, lines, tid, pos0, kp, v, branch)
    rng = np.random.default_rng(seed)
    # the estimate: odometry with a scale error inside margin.distance_pct (2 %)
    m = truth.s.size
    t = np.arange(m) * DT
    s_est, d_est = truth.s * (1 + scale), truth.d * (1 + scale)
    tr = Travel(t, d_est, s_est, np.abs(v[:m]), np.ones(m, dtype=np.int8), np.ones(m, dtype=bool), np.zeros(m), n)
    km0 = float(tl.km_of_pos(pos0))
    aids: list[object] = [Start(tl.line_code, tl.track, km0, kp * tl.km_sign), TopologyAid(lines, MARGIN)]
    # yaw: the truth's turnout signature + a bias and noise within the model (≤ 2σ)
    sigma = math.radians(CFG.gyro_bias_dps)
    wz = truth.wz + rng.uniform(-2, 2) * sigma + rng.normal(0, math.radians(CFG.gyro_noise_dps_rthz) / math.sqrt(DT), m)
    aids.append(TrackImuAid(wz, turnouts(n.switches), lines, CFG, MARGIN))
    if gps:  # 1 Hz fixes: a common bias (≤ 2σ of the slow error) and white noise
        g = GpsConfig()
        j = np.arange(0, m, 10)
        ll = np.array([latlon(lines, truth.track[i], float(truth.pos[i])) for i in j])
        k = math.pi / 180.0 * _R
        east = bias * g.noise_sigma_m * 2 / 1.5 + rng.normal(0, g.noise_white_m, j.size)
        lat = ll[:, 0] + rng.normal(0, g.noise_white_m, j.size) / k
        lon = ll[:, 1] + east / (k * math.cos(math.radians(ll[0, 0])))
        aids.append(TrackGpsAid(t[j], lat, lon, lines, CFG, g))
    sol = run_aids(tr, aids, MARGIN)  # type: ignore[arg-type]
    p = sol.positions
    det = (p["state"] == "determined").to_numpy()
    claimed = p["track_id"].fillna("").astype(object).to_numpy()
    wrong = det & (claimed != np.array(truth.track, dtype=object))
    assert not wrong.any(), (
        f"wrong claim at t={t[np.argmax(wrong)]:.1f}: {claimed[np.argmax(wrong)]} vs {truth.track[np.argmax(wrong)]}"
    )
