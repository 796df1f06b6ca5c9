"""The engine with the standard aids, for hand-made cycles and odometry in the tests."""

from __future__ import annotations

import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.aid import Aid
from fieldlogs.pipeline.aids.balise import BaliseAid, BaliseDb, telegram_rows
from fieldlogs.pipeline.aids.failsafe import FailsafeAid
from fieldlogs.pipeline.aids.feature_aid import FeatureAid
from fieldlogs.pipeline.aids.features import FeatureUnit
from fieldlogs.pipeline.aids.gps import GpsAid
from fieldlogs.pipeline.aids.rail import RailAid
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.types import GpsAnalysis, Odometry


def solve(
    c: Cycles,
    odo: Odometry,
    telegrams: pd.DataFrame | None,
    balise_db: BaliseDb,
    cfg: PipelineConfig,
    *,
    gps: GpsAnalysis | None = None,
    features: FeatureUnit | None = None,
    network: Network | None = None,
) -> Solution:
    """Rail, fail-safe and balise aids, plus GPS and feature points when given."""
    rows = [] if telegrams is None else telegram_rows(telegrams)
    aids: list[Aid] = [RailAid(c.t, c.pto), FailsafeAid(odo.episodes), BaliseAid(balise_db, cfg.balise, rows)]
    if gps is not None:
        aids.append(GpsAid(gps, cfg.gps))
    if features is not None:
        aids.append(FeatureAid(features))
    return run_aids(Travel.of(c, odo, network), aids, cfg.margin)
