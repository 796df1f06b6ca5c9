"""``--propose``: moves keep the C balises' travel distances consistent; a change that would
break a ``db validate`` rule is not applied; the output is written atomically."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.sources import read_source_set
from fieldlogs.config import SuiteConfig
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.propose import (
    CHANGE_COLUMNS,
    Proposal,
    _guard,
    apply_balise_moves,
    build_proposal,
    write_proposal,
)
from fieldlogs.survey.propose import Change as _Change
from schemas.errors import RefusedError
from schemas.settings import SettingError

B = pd.DataFrame(
    {
        "balise_id": ["I1", "I2", "C1", "C2", "UI1", "UC1"],
        "kind": ["I1", "I2", "C", "C", "I1", "C"],
        "line_code": "0420",
        "station_code": ["01", "01", "01", "01", "02", "02"],
        "track": ["D", "D", "D", "D", "U", "U"],
        "signal_type": [None, None, "home", "block", None, "home"],
        "km_actual_m": [1000.0, 1005.0, 2000.0, 3000.0, 5000.0, 4000.0],
        "km_equipment_m": [1000.0, 1005.0, 2000.0, 3000.0, 5000.0, 4000.0],
        "dist_from_initial_m": [np.nan, np.nan, 1000.0, 2000.0, np.nan, 1000.0],
    }
)


def test_moving_a_c_balise_moves_its_travel_distance_with_it() -> None:
    out = apply_balise_moves(B, {"C1": 2.5, "UC1": 1.5}).set_index("balise_id")
    assert out.loc["C1", "km_actual_m"] == 2002.5 and out.loc["C1", "km_equipment_m"] == 2002.5
    assert out.loc["C1", "dist_from_initial_m"] == 1002.5
    assert out.loc["UC1", "dist_from_initial_m"] == 998.5  # up track: km decreases away from the pair
    assert out.loc["C2", "dist_from_initial_m"] == 2000.0


def test_moving_an_i1_moves_the_distance_of_every_c_it_governs() -> None:
    out = apply_balise_moves(B, {"I1": 1.0}).set_index("balise_id")
    assert out.loc[["C1", "C2"], "dist_from_initial_m"].tolist() == [999.0, 1999.0]
    assert out.loc["UC1", "dist_from_initial_m"] == 1000.0


def test_a_change_that_breaks_a_rule_is_not_applied(sample_db: Path) -> None:
    net = read_network(sample_db)
    ok = _Change("balises", "move", "0420-D-C002", "0420", "D", "", "", "", {"balise_id": "0420-D-C002"}, 2.0)
    bad = _Change(
        "balises",
        "move",
        "0420-03-D-I2",
        "0420",
        "D",
        "",
        "",
        "",
        {"balise_id": "0420-03-D-I2", "pair": ("0420", "03", "D")},
        3.0,  # the pair would be 8 m apart: balise.pair_spacing
    )
    proposed = _guard(net, [ok, bad])
    assert ok.applied and not bad.applied
    assert "balise.pair_spacing" in bad.note
    b = proposed.balises.set_index("balise_id")
    assert b.loc["0420-D-C002", "km_actual_m"] == 23471.0
    assert b.loc["0420-03-D-I2", "km_actual_m"] == 20816.0


def test_the_proposal_is_written_atomically_and_refused_when_it_exists(sample_db: Path, tmp_path: Path) -> None:
    net = read_network(sample_db)
    changes = pd.DataFrame(columns=list(CHANGE_COLUMNS))
    out = write_proposal(Proposal(net, changes), tmp_path / "src")
    assert {p.name for p in out.iterdir()} >= {"balises.csv", "gis.csv", "feature_points.csv", "survey_changes.json"}
    back, findings = read_source_set(out)
    assert not [f for f in findings if f.severity == "error"]
    assert len(back.balises) == len(net.balises)
    with pytest.raises(RefusedError):
        write_proposal(Proposal(net, changes), out)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


def test_nothing_flagged_proposes_nothing(sample_db: Path) -> None:
    class Empty:
        network = read_network(sample_db)
        balises = pd.DataFrame({"status": pd.Series([], dtype=str)})
        candidates = pd.DataFrame()
        features = pd.DataFrame({"status": pd.Series([], dtype=str)})
        curves: ClassVar[dict[tuple[str, str], object]] = {}

    p = build_proposal(Empty())
    assert p.changes.empty and p.network is Empty.network


def test_survey_settings_are_in_the_tree_and_range_checked() -> None:
    assert SuiteConfig().survey == SurveyConfig()
    tree = SuiteConfig.from_dict({"survey": {"moved_min_m": 2.0}})
    assert tree.survey.moved_min_m == 2.0
    with pytest.raises(SettingError, match=r"survey\.wheel_alert_share"):
        SuiteConfig.from_dict({"survey": {"wheel_alert_share": 1.5}})
