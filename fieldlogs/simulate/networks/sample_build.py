"""Regenerate the bundled sample network from the copied raw data.

    .venv/bin/python -m fieldlogs.simulate.networks.sample_build [--plot fit.png]

Steps: fit an alignment to the real polyline (:mod:`fieldlogs.simulate.networks.sample_fit`), set the
kilometrage (Kawagoe station = 16k100, its distance from Ōmiya where the line's km starts),
synthesise a gradient profile, survey both tracks (``survey/centrelines.csv``) and
kilometre posts every 1 km and at the stations (``survey/kmposts.csv``), turn the survey
into ``sources/gis.csv`` with the ``gis grid`` code, derive balises and feature points from
the alignment, write ``fit_report.json``, add the station, crossovers and junction
(:mod:`fieldlogs.simulate.networks.sample_junctions`), then build and validate the DB as a check.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.build import build_db
from dbtools.gis.io import grid_files
from dbtools.network import canonical
from dbtools.sample_network import PACKAGE_DIR
from fieldlogs.simulate.networks.alignment import Alignment
from fieldlogs.simulate.networks.sample_fit import FitResult, FitSettings, fit_alignment, project_brute
from fieldlogs.simulate.networks.sample_junctions import add_network
from fieldlogs.simulate.networks.survey import centreline_vertices, km_posts
from fieldlogs.simulate.networks.synthetic import LineSpec, Station, balises, feature_points
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.model import Table
from schemas.tables import BALISES, FEATURE_POINTS, GIS_SPACING_M, LINES

RAILWAY_ID = "JR-East.Kawagoe"
LINE_CODE = "0420"
LINE_NAME = "Kawagoe Line (sample)"
#: Kilometrage of Kawagoe station: its distance from Ōmiya, where the Kawagoe Line's km starts.
KAWAGOE_KM_M = 16_100.0
#: Assumed (invented, plausible) orthometric heights of the stations' rails [m], by English name.
STATION_HEIGHTS_M = {
    "Kawagoe": 19.0,
    "Nishi-Kawagoe": 17.0,
    "Matoba": 24.0,
    "Kasahata": 33.0,
    "Musashi-Takahagi": 47.0,
    "Komagawa": 57.0,
}
#: Assumed geoid height of the area [m]: GIS heights are above the ellipsoid.
GEOID_HEIGHT_M = 38.0
#: Track level this far either side of a station centre [m].
STATION_LEVEL_HALF_M = 200.0
#: Length of every vertical curve (gradient change, linear in chainage) [m].
VERTICAL_CURVE_M = 200.0
#: Steepest synthesised gradient (fraction).
MAX_GRADE = 0.015
#: The realigned stretch where equipment km = actual km + shift: from this far after the
#: first station to this far before the second (station codes) [m].
REALIGNED = ("04", "05", 300.0, 12.0)
#: Survey vertex spacing along each track [m] and kilometre post spacing [m].
VERTEX_SPACING_M = 10.0
POST_SPACING_M = 1000.0

RAW_DIR = PACKAGE_DIR / "raw"
SOURCES_DIR = PACKAGE_DIR / "sources"
SURVEY_DIR = PACKAGE_DIR / "survey"
REPORT_FILE = PACKAGE_DIR / "fit_report.json"


def read_raw(raw_dir: Path = RAW_DIR) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The copied mini-tokyo-3d rows: line vertices (in ``seq`` order) and stations."""
    line = pd.read_csv(raw_dir / "kawagoe_line.csv")
    line = line[line["railway_id"] == RAILWAY_ID].sort_values("seq", kind="stable").reset_index(drop=True)
    stations = pd.read_csv(raw_dir / "kawagoe_stations.csv")
    stations = stations[stations["railway_id"] == RAILWAY_ID].sort_values("station_seq").reset_index(drop=True)
    return line, stations


def grade_knots(station_s: list[float], heights: list[float]) -> list[tuple[float, float]]:
    """Level track around each station, one constant gradient between neighbours, every
    change spread over a vertical curve: the gradient reaches the next station's height."""
    knots: list[tuple[float, float]] = [(0.0, 0.0)]
    for (s0, h0), (s1, h1) in zip(
        zip(station_s[:-1], heights[:-1], strict=True), zip(station_s[1:], heights[1:], strict=True), strict=True
    ):
        a, b = s0 + STATION_LEVEL_HALF_M, s1 - STATION_LEVEL_HALF_M
        # rise = g·(b − a − Lv): the two ramps count half
        g = (h1 - h0) / (b - a - VERTICAL_CURVE_M)
        if abs(g) > MAX_GRADE:
            raise ValueError(f"gradient {g * 1000:.1f} ‰ between chainage {s0:.0f} and {s1:.0f} is too steep")
        knots += [(a, 0.0), (a + VERTICAL_CURVE_M, g), (b - VERTICAL_CURVE_M, g), (b, 0.0)]
    return knots


@dataclass
class Sample:
    spec: LineSpec
    fit: FitResult
    station_offsets_m: list[float]
    chainage_m: np.ndarray
    """Chainage of each raw vertex's foot on the sample centreline."""
    deviation_m: np.ndarray
    """Signed distance of each raw vertex from the sample centreline (left positive)."""
    inside: np.ndarray
    """Raw vertices whose foot lies inside the sample (not beyond its trimmed ends)."""
    cut_m: float
    """Chainage of the fitted line where the sample starts (trimmed to a 20 m multiple of km)."""

    @property
    def rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.deviation_m[self.inside] ** 2)))

    @property
    def max_m(self) -> float:
        return float(np.max(np.abs(self.deviation_m[self.inside])))


def deviation(a: Alignment, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(foot chainage, signed offset, foot inside the line) of plane points on a centreline."""
    sa = np.append(np.arange(0.0, a.length_m, 1.0), a.length_m)
    xa, ya = a.xy(sa)
    s, off = project_brute(x, y, sa, xa, ya)
    return s, off, (s > 1e-6) & (s < a.length_m - 1e-6)


def make_spec(fit: FitResult, stations: pd.DataFrame) -> Sample:
    """Kilometrage, stations, gradient profile and the realigned stretch on the fitted line,
    trimmed to whole 20 m grid cells so that the line and its GIS grid cover the same kms."""
    a0 = fit.alignment
    sx, sy = fit.projector.to_xy(stations["lon"].to_numpy(), stations["lat"].to_numpy())
    s_st, off, _ = deviation(a0, sx, sy)
    km0_raw = KAWAGOE_KM_M - float(s_st[0])
    km_first = math.ceil(km0_raw / GIS_SPACING_M) * GIS_SPACING_M
    km_last = math.floor((km0_raw + a0.length_m) / GIS_SPACING_M) * GIS_SPACING_M
    cut = km_first - km0_raw
    (x0,), (y0,) = a0.xy([cut])
    curves = [replace(c, start_m=c.start_m - cut) for c in a0.curves]
    s_st = s_st - cut
    names = stations["name_en"].tolist()
    heights = [STATION_HEIGHTS_M[n] + GEOID_HEIGHT_M for n in names]
    alignment = Alignment(
        km_last - km_first,
        curves,
        x0=float(x0),
        y0=float(y0),
        heading0=float(a0.heading([cut])[0]),
        km0=float(km_first),
        grade_knots=grade_knots([float(v) for v in s_st], heights),
        height0=heights[0],
    )
    st = [
        Station(f"{i + 1:02d}", name, float(round(km_first + s)))
        for i, (name, s) in enumerate(zip(names, s_st, strict=True))
    ]
    by_code = {x.code: x for x in st}
    first, second, margin, shift = REALIGNED
    shifts = [(by_code[first].km_m + margin, by_code[second].km_m - margin, shift)]
    spec = LineSpec(LINE_CODE, LINE_NAME, alignment, st, equipment_shifts=shifts)
    chainage, dev, inside = deviation(alignment, fit.x, fit.y)
    return Sample(spec, fit, [round(float(v), 1) for v in off], chainage, dev, inside, cut)


def post_kms(spec: LineSpec) -> np.ndarray:
    """Both ends of the surveyed section, every whole kilometre and every station."""
    a = spec.alignment
    whole = np.arange(np.ceil(a.km0 / POST_SPACING_M), np.floor(a.km_end / POST_SPACING_M) + 1) * POST_SPACING_M
    return np.unique(np.concatenate([[a.km0, a.km_end], whole, [s.km_m for s in spec.stations]]))


def write_table(table: Table, frame: pd.DataFrame, path: Path) -> None:
    cols = [c for c in table.column_names if c != "attributes_json"]
    canonical(table, frame)[cols].to_csv(path, index=False, lineterminator="\n")


def fit_report(sample: Sample) -> dict[str, object]:
    spec, fit = sample.spec, sample.fit
    a = spec.alignment
    return {
        "source": "nagix/mini-tokyo-3d (MIT licence, Copyright nagix; station data originally ODPT)",
        "railway_id": RAILWAY_ID,
        "vertices": int(fit.x.size),
        "vertices_inside": int(sample.inside.sum()),
        "zone": fit.projector.zone,
        "deviation_rms_m": round(sample.rms_m, 2),
        "deviation_max_m": round(sample.max_m, 2),
        "length_m": round(a.length_m, 1),
        "km0_m": a.km0,
        "km_end_m": round(a.km_end, 1),
        "curves": [
            {
                "ts_km_m": round(float(a.km(c.start_m)), 1),
                "st_km_m": round(float(a.km(c.end_m)), 1),
                "direction": "left" if c.left else "right",
                "radius_m": round(c.radius_m, 1),
                "transition_m": round(c.transition_m, 1),
                "arc_m": round(c.arc_m, 1),
                "deflection_deg": round(float(np.degrees((c.arc_m + c.transition_m) / c.radius_m)), 2),
            }
            for c in a.curves
        ],
        "dropped_wiggles": [
            {
                "km_m": round(float(a.km(c.centre_m - sample.cut_m)), 0),
                "deflection_deg": round(float(np.degrees(c.deflection_rad)), 2),
            }
            for c in fit.candidates
            if not c.kept
        ],
        "stations": [
            {"code": s.code, "name": s.name, "km_m": s.km_m, "offset_from_line_m": o}
            for s, o in zip(spec.stations, sample.station_offsets_m, strict=True)
        ],
        "realigned": {
            "km_from_m": spec.equipment_shifts[0][0],
            "km_to_m": spec.equipment_shifts[0][1],
            "shift_m": spec.equipment_shifts[0][2],
        },
    }


def plot_fit(sample: Sample, path: Path) -> None:
    """Raw vs fitted geometry, deviation and curvature profile (for a person to look at)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fit, a = sample.fit, sample.spec.alignment
    s = np.arange(0.0, a.length_m, 2.0)
    x, y = a.xy(s)
    fig, ax = plt.subplots(3, 1, figsize=(12, 13), gridspec_kw={"height_ratios": [2, 1, 1]})
    ax[0].plot(fit.x, fit.y, "o", ms=3, label="mini-tokyo-3d vertices")
    ax[0].plot(x, y, "-", lw=1, label="fitted alignment")
    for c in a.curves:
        cx, cy = a.xy(np.linspace(c.start_m, c.end_m, 50))
        ax[0].plot(cx, cy, "r-", lw=3, alpha=0.4)
    ax[0].set_aspect("equal")
    ax[0].set_title(f"{LINE_NAME}: plane zone {fit.projector.zone} [m]")
    ax[0].legend()
    inside = sample.inside
    ax[1].plot(a.km(sample.chainage_m[inside]), sample.deviation_m[inside], "o-", ms=3)
    ax[1].set_ylabel("vertex − fit [m]")
    ax[1].set_title(f"deviation: RMS {sample.rms_m:.2f} m, max {sample.max_m:.2f} m")
    ax[2].plot(a.km(fit.smoothed_s - sample.cut_m), fit.smoothed_curvature * 1000, lw=0.8, label="smoothed polyline")
    ax[2].plot(a.km(s), a.curvature(s) * 1000, lw=1.2, label="fitted alignment")
    ax[2].set_ylabel("curvature [1/km]")
    ax[2].set_xlabel("km [m]")
    ax[2].legend()
    for axis in ax[1:]:
        axis.grid(True)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def build(settings: FitSettings | None = None, plot: Path | None = None) -> tuple[dict[str, object], list[Finding]]:
    """Regenerate every generated file; returns the fit report and the validation findings."""
    line, stations = read_raw()
    fit = fit_alignment(line["lon"].to_numpy(), line["lat"].to_numpy(), settings)
    sample = make_spec(fit, stations)
    spec, projector = sample.spec, fit.projector

    SURVEY_DIR.mkdir(exist_ok=True)
    SOURCES_DIR.mkdir(exist_ok=True)
    centreline_vertices(spec, projector, VERTEX_SPACING_M).to_csv(
        SURVEY_DIR / "centrelines.csv", index=False, lineterminator="\n"
    )
    posts = km_posts(spec, projector, post_kms(spec)).drop(columns=["km_after_m"])
    posts.to_csv(SURVEY_DIR / "kmposts.csv", index=False, lineterminator="\n")
    grid_files(SURVEY_DIR / "centrelines.csv", SURVEY_DIR / "kmposts.csv", SOURCES_DIR / "gis.csv", force=True)
    write_table(BALISES, balises(spec), SOURCES_DIR / "balises.csv")
    write_table(FEATURE_POINTS, feature_points(spec), SOURCES_DIR / "feature_points.csv")
    write_table(LINES, pd.DataFrame({"line_code": [LINE_CODE], "name": [LINE_NAME]}), SOURCES_DIR / "lines.csv")
    add_network(SOURCES_DIR, PACKAGE_DIR / "network_sources")  # + station, crossovers, junction
    report = fit_report(sample)
    REPORT_FILE.write_text(json.dumps(report, ensure_ascii=False, indent=2) + "\n", encoding="utf-8")
    if plot is not None:
        plot_fit(sample, plot)

    from dbtools.validate import validate_path  # being written alongside; import late

    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "sample.sqlite"
        build_db(PACKAGE_DIR / "network_sources", db, db_version="sample", note="bundled sample network")
        findings = validate_path(db)
    return report, findings


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m fieldlogs.simulate.networks.sample_build", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--plot", type=Path, help="also write a PNG of raw vs fitted geometry and curvature")
    args = parser.parse_args(argv)
    report, findings = build(plot=args.plot)
    curves = report["curves"]
    assert isinstance(curves, list)
    radii = [c["radius_m"] for c in curves]
    print(
        f"fit: {report['vertices']} vertices, {len(curves)} curves, R {min(radii):.0f}–{max(radii):.0f} m, "
        f"deviation RMS {report['deviation_rms_m']} m, max {report['deviation_max_m']} m"
    )
    errors = [f for f in findings if f.severity == Severity.ERROR]
    print(f"validate: {len(errors)} error(s), {len(findings) - len(errors)} warning(s)")
    for f in findings[:50]:
        print(f"  {f}")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
