"""A small straight double-track source set shared by the diff/release/CLI tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.gis.geometry import GEOD


def write_sources(folder: Path, c_km: float = 600.0) -> Path:
    """A straight double-track line 0420, km 0–1000, tracks 3.8 m apart, two initial pairs."""
    folder.mkdir(parents=True)
    km = np.arange(0.0, 1001.0, 20.0)
    n = km.size
    clon, clat, _ = GEOD.fwd(np.full(n, 139.4), np.full(n, 35.9), np.full(n, 90.0), km)
    frames = []
    for track, az in (("D", 0.0), ("U", 180.0)):
        lon, lat, _ = GEOD.fwd(clon, clat, np.full(n, az), np.full(n, 1.9))
        frames.append(pd.DataFrame({"line_code": "0420", "track": track, "km_m": km, "lat": lat, "lon": lon}))
    pd.concat(frames).to_csv(folder / "gis.csv", index=False, float_format="%.10f")
    (folder / "balises.csv").write_text(
        "balise_id,kind,line_code,station_code,track,signal_type,km_actual_m,km_equipment_m,dist_from_initial_m\n"
        "B001,I1,0420,01,D,,100,100,\nB002,I2,0420,01,D,,105,105,\n"
        "B003,I1,0420,01,U,,905,905,\nB004,I2,0420,01,U,,900,900,\n"
        f"B005,C,0420,01,D,H,{c_km},{c_km},{c_km - 100}\n"
    )
    (folder / "feature_points.csv").write_text("line_code,track,feature_id,km_m,radius_m,attribute,role\n")
    return folder
