"""The optional ``radar`` block of ``run.json``: the 2-frequency CW radar [S004 Table 1]
that recorded a run's ``radar_if`` samples, its plausible ranges and what follows from it
(λ, sample rate, frame length, ΔV, Vmax, Rmax); ``parse_radar_block`` checks a block into
findings (read by ``fieldlogs.runs.handle.Run``)."""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from schemas.enums import CabDirection, IqConvention, Severity
from schemas.findings import Finding
from schemas.units import SPEED_OF_LIGHT_MPS


@dataclass(frozen=True)
class RadarField:
    """One number of the optional ``run.json`` block ``radar`` and its plausible range."""

    name: str
    unit: str
    description: str
    min: float
    max: float


#: The ``radar`` block of ``run.json`` (needed to process ``radar_if``); S004 Table 1 values
#: in the descriptions. ``looks_toward`` (optional, ``F`` default) is the vehicle end the beam
#: points to.
RUN_JSON_RADAR: tuple[RadarField, ...] = (
    RadarField("f0_hz", "Hz", "Carrier frequency f0 (Table 1: 24.06 GHz)", 1e9, 300e9),
    RadarField("delta_f_hz", "Hz", "Frequency difference Δf = f2 − f1 (Table 1: 12.75 MHz)", 1e5, 1e9),
    RadarField("t_pri_s", "s", "Switching interval f1 → f2, T_pri (Table 1: 50 µs)", 1e-7, 1e-2),
    RadarField("t_epi_s", "s", "Observation time of one FFT frame, T_epi (Table 1: 307 ms)", 1e-3, 10.0),
    RadarField("height_m", "m", "Antenna height h above the ground (track bed) surface", 0.05, 5.0),
    RadarField("depression_deg", "deg", "Beam axis below the horizontal, toward looks_toward", 5.0, 85.0),
    RadarField("beam_elev_deg", "deg", "Half-power half-width in elevation (Table 1: ±7.5°)", 0.5, 30.0),
    RadarField("beam_az_deg", "deg", "Half-power half-width in azimuth (Table 1: ±3.0°)", 0.5, 30.0),
)
RADAR_LOOKS_TOWARD = (CabDirection.FORWARD.value, CabDirection.REVERSE.value)
#: Optional: how I and Q form the complex signal (``schemas.enums.IqConvention``, ``i+jq`` default).
RADAR_IQ_CONVENTIONS = tuple(c.value for c in IqConvention)
#: Optional: the sample value at the ADC's full scale (``radar_if`` samples are I/full_scale,
#: Q/full_scale in FS, ±1; 1 default: samples already normalised; e.g. 2047 for 12-bit counts).
RADAR_FULL_SCALE = RadarField(
    "full_scale", "counts", "Sample value at the ADC full scale (1: samples already in FS, ±1)", 1e-6, 1e9
)


@dataclass(frozen=True)
class RadarParams:
    """The run's radar [S004 Table 1] and the figures that follow from it."""

    f0_hz: float
    delta_f_hz: float
    t_pri_s: float
    t_epi_s: float
    height_m: float
    depression_deg: float
    beam_elev_deg: float
    beam_az_deg: float
    looks_toward: str = "F"
    iq_convention: str = IqConvention.I_PLUS_JQ.value
    full_scale: float = 1.0

    @property
    def q_sign(self) -> float:
        """+1 for ``i+jq``, −1 for ``i-jq``: z = (I + j·q_sign·Q) / full_scale."""
        return -1.0 if self.iq_convention == IqConvention.I_MINUS_JQ.value else 1.0

    @property
    def wavelength_m(self) -> float:
        """λ = c / f0 (24.06 GHz: 12.46 mm)."""
        return SPEED_OF_LIGHT_MPS / self.f0_hz

    @property
    def sample_rate_hz(self) -> float:
        """Samples per second of each frequency: 1 / (2·T_pri) (10 kHz)."""
        return 1.0 / (2.0 * self.t_pri_s)

    @property
    def samples_per_frame(self) -> int:
        """N = round(T_epi · rate) samples of each frequency per FFT frame (3070)."""
        return max(round(self.t_epi_s * self.sample_rate_hz), 1)

    @property
    def speed_resolution_mps(self) -> float:
        """ΔV = λ / (2·T_epi): one Doppler bin as radial speed (0.073 km/h)."""
        return self.wavelength_m / (2.0 * self.t_epi_s)

    @property
    def v_max_mps(self) -> float:
        """Radial speed at the Doppler Nyquist frequency rate/2: λ·rate/4 (112.14 km/h)."""
        return self.wavelength_m * self.sample_rate_hz / 4.0

    @property
    def r_max_m(self) -> float:
        """Unambiguous range c / (2·Δf) of the phase difference (11.76 m)."""
        return SPEED_OF_LIGHT_MPS / (2.0 * self.delta_f_hz)

    @property
    def look_sign(self) -> int:
        """+1 when the beam looks toward the F end (body +x), −1 toward the R end."""
        return 1 if self.looks_toward == CabDirection.FORWARD.value else -1

    def depression_range_rad(self, beamwidths: float) -> tuple[float, float]:
        """Depression angles of the beam axis ± ``beamwidths`` half-widths, kept in (0.5°, 89.5°)."""
        lo = self.depression_deg - beamwidths * self.beam_elev_deg
        hi = self.depression_deg + beamwidths * self.beam_elev_deg
        return math.radians(max(lo, 0.5)), math.radians(min(hi, 89.5))

    def to_json(self) -> dict[str, float | str]:
        return {f.name: getattr(self, f.name) for f in RUN_JSON_RADAR} | {
            "looks_toward": self.looks_toward,
            "iq_convention": self.iq_convention,
            "full_scale": self.full_scale,
        }


def _suggest(name: str, known: list[str]) -> str | None:
    close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    return close[0] if close else None


def _radar_finding(path: Path, column: str, message: str, **kw: Any) -> Finding:
    return Finding("log.run_json_radar", Severity.ERROR, "run.json", message, file=str(path), column=column, **kw)


def _radar_number(block: dict[str, Any], f: Any, path: Path) -> tuple[float | None, Finding | None]:
    col = f"radar.{f.name}"
    raw = block.get(f.name)
    if raw is None:
        return None, _radar_finding(path, col, f"field '{col}' [{f.unit}] is missing ({f.description})")
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
        return None, _radar_finding(path, col, f"field '{col}' = {raw!r} is not a number [{f.unit}]", value=str(raw))
    if not f.min <= raw <= f.max:
        return None, _radar_finding(
            path, col, f"{col} = {raw:g} {f.unit} is outside {f.min:g}–{f.max:g}", value=raw, limit=[f.min, f.max]
        )
    return float(raw), None


def parse_radar_block(data: dict[str, Any], path: Path) -> tuple[RadarParams | None, list[Finding]]:
    """The optional ``radar`` block of run.json (``RUN_JSON_RADAR``), checked.

    Absent → (None, []). Every field must be a number inside its range; the beam must stay
    between the horizontal and the vertical, and its footprint inside the unambiguous range
    c/(2·Δf). Optional: ``looks_toward`` (F/R), ``iq_convention`` (``RADAR_IQ_CONVENTIONS``,
    ``i+jq`` default) and ``full_scale`` (``RADAR_FULL_SCALE``, 1 default). Any error → (None,
    findings).
    """
    if data.get("radar") is None:
        return None, []
    block = data["radar"]
    if not isinstance(block, dict):
        return None, [_radar_finding(path, "radar", "'radar' must be a JSON object of radar parameters")]
    findings: list[Finding] = []
    values: dict[str, Any] = {}
    for f in RUN_JSON_RADAR:
        v, bad = _radar_number(block, f, path)
        if bad is not None:
            findings.append(bad)
        values[f.name] = v
    looks = block.get("looks_toward", "F")
    if looks not in RADAR_LOOKS_TOWARD:
        findings.append(_radar_finding(path, "radar.looks_toward", f"radar.looks_toward = {looks!r} is not F or R"))
    iq = block.get("iq_convention", IqConvention.I_PLUS_JQ.value)
    if iq not in RADAR_IQ_CONVENTIONS:
        findings.append(
            _radar_finding(
                path,
                "radar.iq_convention",
                f"radar.iq_convention = {iq!r} is not one of {', '.join(RADAR_IQ_CONVENTIONS)}",
            )
        )
    full_scale: float | None = 1.0
    if "full_scale" in block:
        full_scale, bad = _radar_number(block, RADAR_FULL_SCALE, path)
        findings += [bad] if bad is not None else []
    known = {f.name for f in RUN_JSON_RADAR} | {"looks_toward", "iq_convention", "full_scale"}
    for k in sorted(set(block) - known):
        hint = _suggest(k, sorted(known))
        findings.append(
            Finding(
                "log.run_json_radar",
                Severity.WARNING,
                "run.json",
                f"unknown field 'radar.{k}' ignored" + (f" (did you mean '{hint}'?)" if hint else ""),
                file=str(path),
                column=f"radar.{k}",
            )
        )
    if any(f.severity == Severity.ERROR for f in findings):
        return None, findings
    params = RadarParams(**values, looks_toward=looks, iq_convention=iq, full_scale=full_scale or 1.0)
    geometry = _radar_geometry(params, path)
    return (None, findings + geometry) if geometry else (params, findings)


def _radar_geometry(p: RadarParams, path: Path) -> list[Finding]:
    """Cross-field checks: beam between horizontal and vertical, footprint range < c/(2·Δf), frames of ≥ 16 samples."""
    lo, hi = p.depression_deg - p.beam_elev_deg, p.depression_deg + p.beam_elev_deg
    if not (0.0 < lo and hi < 90.0):
        return [
            _radar_finding(
                path,
                "radar.depression_deg",
                f"beam {lo:g}°–{hi:g}° below the horizontal (depression ± beam_elev) must lie between 0° and 90°",
                value=[lo, hi],
                limit=[0, 90],
            )
        ]
    far = p.height_m / math.sin(math.radians(lo))
    if far >= p.r_max_m:
        return [
            _radar_finding(
                path,
                "radar.delta_f_hz",
                f"the beam's far edge is {far:.2f} m away, beyond the unambiguous range c/(2·Δf) = {p.r_max_m:.2f} m",
                value=far,
                limit=p.r_max_m,
            )
        ]
    if p.samples_per_frame < 16:
        return [
            _radar_finding(
                path,
                "radar.t_epi_s",
                f"T_epi holds only {p.samples_per_frame} samples of each frequency (at least 16)",
                value=p.samples_per_frame,
                limit=16,
            )
        ]
    return []
