from __future__ import annotations

from pathlib import Path

import pandas as pd

from dbtools.build import build_db
from dbtools.database import integrity_findings, read_network
from dbtools.gis.geometry import Projector
from dbtools.network import content_hash
from dbtools.sources import read_source_set, write_source_set
from fieldlogs.simulate.networks.synthetic import build_network, demo_line


def test_source_roundtrip_is_exact(tmp_path: Path) -> None:
    net = build_network([demo_line()], Projector(9))
    write_source_set(net, tmp_path / "src")
    back, findings = read_source_set(tmp_path / "src")
    assert findings == []
    assert content_hash(back.tables) == content_hash(net.tables)
    build_db(tmp_path / "src", tmp_path / "net.sqlite")
    assert integrity_findings(tmp_path / "net.sqlite") == []
    db = read_network(tmp_path / "net.sqlite")
    pd.testing.assert_frame_equal(db.gis, net.gis)


def test_feature_rows_in_running_order() -> None:
    fp = build_network([demo_line()], Projector(9)).feature_points
    for (_, track, _), g in fp.groupby(["line_code", "track", "feature_id"]):
        g = g.sort_values("seq")
        steps = g["km_m"].diff().dropna()
        assert (steps > 0).all() if track == "D" else (steps < 0).all()
        assert g["attribute"].tolist()[0] == "straight" and g["attribute"].tolist()[-1] == "none"
