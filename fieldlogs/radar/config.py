"""Tunable limits of the radar processing (units in the names)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RadarConfig:
    """Thresholds of ``fieldlogs.radar`` (the radar itself is run.json's ``radar`` block)."""

    pfa: float = 1e-6
    """False-alarm probability per bin of the noise-floor threshold (CFAR): a line needs
    power > −ln(pfa) × the mean noise power of a bin (1e-6: 13.8×, +11.4 dB)."""
    dc_guard_bins: int = 2
    """Bins either side of 0 Hz never taken as a Doppler line (the Hann main lobe of a
    static echo); sets the lowest measurable speed."""
    gate_beamwidths: float = 2.0
    """A line is a ground reflection when its range lies where the ground is seen at the
    beam axis ± this many elevation half-widths: h/sin(θ0 + k·β) ≤ R ≤ h/sin(θ0 − k·β)."""
    core_beamwidths: float = 1.5
    """Refinement: only lines whose Doppler puts them within the beam axis ± this many
    elevation half-widths (cos θ_m = V_m/V_G) — toward the beam edges the spectrum's
    resolution smears the strong centre into the weak edge bins and pulls their ranges
    toward the centre's."""
    core_speed_mps: float = 9.0
    """Below this ground speed the beam core narrows in proportion to the speed, to
    ``core_beamwidths``·V/``core_speed_mps``: one Doppler bin spans the angle
    ΔV/(V·sin θ0), which grows as 1/V, and with it the beam pattern's pull on the edge
    lines' ranges (at walking pace −4.5 cm at 33°: bench/NOTES.md)."""
    core_min_beamwidths: float = 0.5
    """The narrowest beam core (at the slowest speeds) [elevation half-widths]."""
    gate_sigmas: float = 3.0
    """Refinement: lines whose range is more than this many σ_R from the one eq. 1
    predicts for their Doppler are left out (symmetric, so the gate adds no bias)."""
    range_floor_m: float = 0.01
    """Smallest σ_R of one line [m] (speckle: reflections of one bin spread in range)."""
    sigma_scale: float = 1.45
    """The Gauss–Newton 1σ times this: the lines of one frame share errors their scatter
    does not show (speckle of the same ground, acceleration during T_epi). Set so that
    simulated errors are within 1σ about 68 % of the time (bench/NOTES.md); re-tune on
    field runs against a reference speed."""
    iterations: int = 6
    """Gauss–Newton steps of the range-space refinement of eq. 2."""
    min_lines: int = 1
    """Fewer used ground lines → low_quality. One line suffices for eq. 1 (its own range
    corrects its own Doppler): at walking pace a frame resolves only a few lines."""
    min_direction: float = 0.8
    """|Σ sign(f_d)·(snr − snr_mirror)| / Σ (snr + snr_mirror) of the ground lines below
    this → no clear direction of motion (vibration sidebands on both sides of 0 Hz):
    standstill when slow (``vibration_max_mps``), else low_quality."""
    vibration_max_mps: float = 0.3
    """A frame with a static ground echo whose lines have no clear direction and are all
    slower than this [m/s] is standstill: the sidebands of the antenna's vibration."""
    alias_share: float = 0.1
    """Aliased when the lines at a ground range only if shifted by c/(4·Δf) are at least
    this share of all ground-range lines (and at least ``min_alias_lines``)."""
    min_alias_lines: int = 3
    min_valid: float = 0.9
    """Frames with a smaller share of their samples present → low_quality."""
    max_sigma_mps: float = 0.5
    """A speed whose 1σ exceeds this [m/s] … """
    max_rel_sigma: float = 0.02
    """… and this share of the speed → low_quality."""
    block_frames: int = 256
    """Frames per vectorised block (bounds memory; the result does not depend on it beyond
    the last bit of the float32 FFTs)."""
