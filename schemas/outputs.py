"""Outputs: the pipeline's (``trainpos run``) positions per cycle and events; the radar's
(``trainpos radar speed``) ground speed per frame."""

from __future__ import annotations

from schemas.enums import PositionState, RadarStatus
from schemas.model import Column, Table

POSITIONS = Table(
    name="positions",
    kind="output",
    description="One row per 100 ms cycle: what the onboard unit concluded.",
    columns=(
        Column("t", "float", "Cycle time", unit="s"),
        Column(
            "state",
            "str",
            "undetermined, determined, uncertain or ambiguous (candidate tracks in candidates)",
            enum=tuple(s.value for s in PositionState),
        ),
        Column("line_code", "str", "Line", nullable=True),
        Column(
            "track",
            "str",
            "Local track name: U/D/S on a line; on a network also a station track's (1, 2…)",
            nullable=True,
        ),
        Column(
            "track_id",
            "str",
            "Network track (netElement) claimed; on a line-only DB the implied LINE:TRACK",
            nullable=True,
        ),
        Column("pos_m", "float", "Distance along that track from its begin", unit="m", nullable=True),
        Column("km_m", "float", "Actual kilometrage", unit="m", nullable=True),
        Column("km_equipment_m", "float", "Equipment kilometrage", unit="m", nullable=True),
        Column("speed_mps", "float", "Speed estimate", unit="m/s"),
        Column("margin_m", "float", "Safety margin: |km error| ≤ margin", unit="m", nullable=True),
        Column("last_fix_source", "str", "balise, feature, gps, gnss or none", nullable=True),
        Column("km_head_m", "float", "km of the vehicle's leading end (needs its geometry)", unit="m", nullable=True),
        Column(
            "km_tail_m", "float", "km of its trailing end: the vehicle occupies [tail, head]", unit="m", nullable=True
        ),
        Column(
            "candidates",
            "str",
            "State ambiguous: JSON list of the candidate tracks, each "
            '{"track_id", "pos_m", "km_m" (null off a line), "margin_m"}',
            nullable=True,
        ),
    ),
)

EVENTS = Table(
    name="events",
    kind="output",
    description="Events: corrections, refusals, slips, anomalies, fail-safe.",
    columns=(
        Column("t", "float", "Time", unit="s"),
        Column("type", "str", "Event type"),
        Column("km_m", "float", "Kilometrage at the event", unit="m", nullable=True),
        Column("correction_m", "float", "Correction amount (computed − DB)", unit="m", nullable=True),
        Column("correction_pct", "float", "Position-correction percentage", unit="%", nullable=True),
        Column("detail", "str", "Human-readable detail / JSON", nullable=True),
    ),
)


def _opt(name: str, what: str, unit: str = "") -> Column:
    return Column(name, "float", what, unit=unit, nullable=True)


RADAR_SPEED = Table(
    name="radar_speed",
    kind="output",
    description="2-frequency CW radar ground speed [S004], one row per T_epi frame of radar_if.",
    columns=(
        Column("t", "float", "Frame centre", unit="s"),
        _opt("speed_mps", "Ground speed V_G, + toward the F end (ok, standstill; else empty)", "m/s"),
        _opt("sigma_mps", "1σ uncertainty of speed_mps", "m/s"),
        Column("status", "str", "Frame status", enum=tuple(s.value for s in RadarStatus)),
        Column("n_lines", "int", "Paired f1/f2 Doppler lines above the noise threshold", min=0),
        Column("n_used", "int", "Lines at a ground range used for V_G (eq. 2)", min=0),
        Column("n_alias", "int", "Lines at a ground range only if aliased (range shifted c/(4·Δf))", min=0),
        _opt("residual_m", "Weighted RMS of measured − predicted range of the used lines", "m"),
        _opt("eq1_rms", "RMS of eq. 1's residual (h/R)² + (V_m/V_G)² − 1 of the used lines"),
        _opt("snr_db", "Median signal-to-noise ratio of the used lines", "dB"),
        _opt("v_eq2_mps", "The paper's eq. 2 in closed form, unweighted (signed)", "m/s"),
        _opt("v_naive_mps", "Strongest line only: f_d·λ/(2·cos depression) (signed)", "m/s"),
        Column("valid_share", "float", "Share of the frame's samples present", min=0.0, max=1.0),
    ),
)

OUTPUT_TABLES: dict[str, Table] = {t.name: t for t in (POSITIONS, EVENTS, RADAR_SPEED)}
