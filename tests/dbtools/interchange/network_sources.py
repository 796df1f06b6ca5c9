"""A source set with declared topology, made from the sample line 0420 (U and D, km 16k000 to
30k980, about 4 m apart): D and U each split at a switch, a crossover X1 from D km 25k000 to
U km 25k100 (its centreline in track_points, straight between the two switch toes), two
point switches W1 (on D, 1:9, diverging right) and W2 (on U, 1:9, diverging left), the six
switch connections, and one ETCS balise group 3:12 of two G balises on D near km 24k000."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.sample_network import sample_source_dir

TRACK_IDS = ("D1", "D2", "U1", "U2", "X1")
SWITCH_IDS = ("W1", "W2")
KM_LO, KM_HI, KM_D, KM_U = 16000.0, 30980.0, 25000.0, 25100.0


def _at(g: pd.DataFrame, track: str, km: float) -> tuple[float, float]:
    t = g[(g["track"] == track) & (g["km_m"] == km)]
    return float(t["lat"].iloc[0]), float(t["lon"].iloc[0])


def crossover_points(g: pd.DataFrame) -> pd.DataFrame:
    """X1 every 20 m (and its end) on the straight from D km 25k000 to U km 25k100."""
    from pyproj import Geod

    (la0, lo0), (la1, lo1) = _at(g, "D", KM_D), _at(g, "U", KM_U)
    geod = Geod(ellps="GRS80")
    length = float(geod.inv(lo0, la0, lo1, la1)[2])
    pos = np.append(np.arange(0.0, length, 20.0), length)
    f = pos / length
    return pd.DataFrame(
        {
            "track_id": "X1",
            "pos_m": np.round(pos, 3),
            "km_m": np.nan,
            "lat": la0 + f * (la1 - la0),
            "lon": lo0 + f * (lo1 - lo0),
            "height_m": np.nan,
        }
    )


def write_topology_sources(dst: Path) -> Path:
    """The sample source set plus the network above, in ``dst``."""
    shutil.copytree(sample_source_dir(), dst)
    g = pd.read_csv(dst / "gis.csv", dtype={"line_code": str})
    x1 = crossover_points(g)
    x1.to_csv(dst / "track_points.csv", index=False)
    row = {"line_code": "0420", "kind": "main"}
    tracks = [
        {**row, "track_id": "D1", "track": "D", "km_begin_m": KM_LO, "km_end_m": KM_D},
        {**row, "track_id": "D2", "track": "D", "km_begin_m": KM_D, "km_end_m": KM_HI},
        {**row, "track_id": "U1", "track": "U", "km_begin_m": KM_LO, "km_end_m": KM_U},
        {**row, "track_id": "U2", "track": "U", "km_begin_m": KM_U, "km_end_m": KM_HI},
        {"track_id": "X1", "line_code": None, "track": None, "kind": "crossover", "km_begin_m": None, "km_end_m": None},
    ]
    for t in tracks:
        t["length_m"] = float(x1["pos_m"].iloc[-1]) if t["track_id"] == "X1" else t["km_end_m"] - t["km_begin_m"]
    pd.DataFrame(tracks).to_csv(dst / "tracks.csv", index=False)
    switches = [
        ("W1", ("D1", "end"), ("D2", "begin"), ("X1", "begin"), "right", KM_D, "D"),
        ("W2", ("U2", "begin"), ("U1", "end"), ("X1", "end"), "left", KM_U, "U"),
    ]
    sw_rows, conn = [], []
    for sid, a1, b1, b2, side, km, track in switches:
        sw_rows.append(
            {
                "switch_id": sid,
                "type": "point",
                "a1_track": a1[0],
                "a1_end": a1[1],
                "b1_track": b1[0],
                "b1_end": b1[1],
                "b2_track": b2[0],
                "b2_end": b2[1],
                "diverging_side": side,
                "switch_number": 9.0,
                "diverging_radius_m": 190.0,
                "diverging_speed_kmh": 40.0,
                "line_code": "0420",
                "km_m": km,
            }
        )
        _ = track
        for (ta, ea), (tb, eb), nav in ((a1, b1, "both"), (a1, b2, "both"), (b1, b2, "none")):
            conn.append({"track_a": ta, "end_a": ea, "track_b": tb, "end_b": eb, "navigability": nav, "switch_id": sid})
    pd.DataFrame(sw_rows).to_csv(dst / "switches.csv", index=False)
    pd.DataFrame(conn).to_csv(dst / "connections.csv", index=False)
    b = pd.read_csv(dst / "balises.csv", dtype=str, keep_default_na=False)
    group = pd.DataFrame(
        {
            "balise_id": ["BG-3-12-0", "BG-3-12-1"],
            "kind": "G",
            "line_code": "0420",
            "track": "D",
            "km_actual_m": ["24000.0", "24003.0"],
            "km_equipment_m": ["24000.0", "24003.0"],
            "track_id": "D1",
            "nid_c": "3",
            "nid_bg": "12",
            "n_pig": ["0", "1"],
            "n_total": "2",
        }
    )
    pd.concat([b, group], ignore_index=True).fillna("").to_csv(dst / "balises.csv", index=False)
    return dst
