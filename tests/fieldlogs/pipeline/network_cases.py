"""Shared pieces of the network positioning tests: the hand-made networks
(tests/data/networks), synthetic travel and an initial fix."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dbtools.network import Network
from dbtools.sources import read_source_set
from fieldlogs.pipeline.aid import Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.config import MarginConfig, TrackSelectConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.types import Fix
from schemas.enums import FixSource

NETWORKS = Path(__file__).resolve().parents[2] / "data" / "networks"
_NETS: dict[str, Network] = {}
MARGIN = MarginConfig()
CFG = TrackSelectConfig()


def net(name: str) -> Network:
    if name not in _NETS:
        _NETS[name] = read_source_set(NETWORKS / name)[0]
    return _NETS[name]


def travel(network: Network, v: np.ndarray, cab: int = 1) -> Travel:
    """Travel at speeds ``v`` (signed: + toward the F end) on a 0.1 s grid, cab ``cab``."""
    n = v.size
    t = np.arange(n, dtype=np.float64) * 0.1
    ds = np.concatenate([[0.0], np.cumsum(v[:-1] * 0.1)])
    d = np.concatenate([[0.0], np.cumsum(np.abs(v[:-1]) * 0.1)])
    return Travel(
        t, d, ds * cab, np.abs(v), np.full(n, cab, dtype=np.int8), np.ones(n, dtype=bool), np.zeros(n), network
    )


class Start(StaticAid):
    """An S003-like initial fix at t = 0 on a line, track and km."""

    name = "start"
    priority = Priority.TELEGRAM

    def __init__(self, line: str, track: str, km: float, k: int) -> None:
        self.fix = (line, track, km, k)

    def observations(self) -> list[Observation]:
        return [Observation(0.0)]

    def observe(self, obs: Observation, view: object) -> Outcome:
        line, track, km, k = self.fix
        return Outcome([], Fix(0.0, 0.0, 0.0, km, km, line, track, k, FixSource.BALISE, 1.0))
