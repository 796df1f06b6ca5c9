"""Tuning of ``db validate``: every limit in one place, with its unit and why it is what it is."""

from __future__ import annotations

from dataclasses import dataclass

from schemas.tables import FEATURE_TOLERANCE, GIS_SPACING_M, PAIR_SPACING_M, TRACK_SPACING_M


@dataclass(frozen=True)
class ValidationConfig:
    """Limits of the consistency rules (SPEC §3). Defaults are what ``db validate`` uses."""

    # -- balises ---------------------------------------------------------------------------
    pair_spacing_m: float = PAIR_SPACING_M
    """Nominal distance between I1 and I2 of an initial pair [m]."""
    pair_spacing_tolerance_m: float = 0.5
    """Allowed deviation from ``pair_spacing_m`` (rule ``balise.pair_spacing``) [m]."""
    id_window_m: float = 500.0
    """C-balise identification window: two C balises with the same signal type after the same
    pair whose ``dist_from_initial_m`` differ by ≤ this are ambiguous (``balise.ambiguous``) [m].
    Same value as the pipeline's ``BaliseConfig.id_window_m``."""
    km_equipment_tolerance_m: float = 1000.0
    """|km_equipment_m − km_actual_m| of a balise above this: error (``balise.km_equipment``)
    [m]. The equipment km is the actual km of an older survey; re-surveys move it by metres to
    hundreds of metres, never by kilometres — beyond, one of them was typed wrong (23469.0 →
    234690.0)."""
    dist_tolerance_m: float = 1.0
    """``dist_from_initial_m`` vs |km_actual(C) − km_actual(I1)|: warning beyond this
    (``balise.dist_from_initial``) [m]. The stored value is a travel distance, so it may
    legitimately differ a little from the km difference (survey rounding)."""

    # -- GIS grid --------------------------------------------------------------------------
    gis_spacing_m: float = GIS_SPACING_M
    """Grid step of the GIS kilometrage (``gis.km_grid``, ``gis.km_step``) [m]."""
    km_epsilon_m: float = 1e-3
    """Two kilometrages closer than this are equal (float noise in sources) [m]."""
    step_tolerance_m: float = 0.5
    """Geodesic distance of consecutive points vs their km difference: absolute part of the
    tolerance (``gis.step_length``) [m]."""
    step_tolerance_rel: float = 0.01
    """… plus this fraction of the km difference [–]. Together they cover survey noise, the
    chord being shorter than the arc (L³/24R² = 8 mm for 20 m at R = 200 m) and the parallel
    track of a double-track line being shorter/longer than the centreline its km is measured
    on (d/R = 1.9/300 = 0.6 % on a 300 m curve)."""
    spike_max_turn_rad: float = 0.1
    """Largest plausible angle between consecutive 20 m segments [rad]; 0.1 rad ≈ a radius of
    200 m (``gis.spike``). Lower it for high-speed lines, raise it for tramways."""
    track_spacing_m: float = TRACK_SPACING_M
    """Nominal distance between the up and down track centres [m]."""
    track_spacing_warning_m: float = 3.5
    """U/D points with the same km closer than this where the tracks are parallel: warning
    (``gis.track_spacing``) [m]; 0.3 m below nominal allows for survey error of both tracks."""
    track_spacing_error_m: float = 2.5
    """… closer than this: error [m]. Below it the GPS up/down decision (fix accuracy ~2 m)
    cannot work and the grid is very likely wrong."""
    parallel_max_rad: float = 0.01
    """Tracks count as parallel where their headings at the same km differ by less than this
    [rad] (0.2 m of lateral change per 20 m step); elsewhere (turnouts, tracks joining or
    diverging) the spacing rule does not apply."""

    # -- feature points --------------------------------------------------------------------
    feature_tolerance: float = FEATURE_TOLERANCE
    """GIS curvature over the curve body must lie within (1/R)(1 ± this) (``feature.radius``) [–]."""
    straight_kappa_max: float = 1 / 4000
    """|κ| below which the track counts as straight [1/m] (same as the pipeline's
    ``FeatureConfig.straight_kappa_max``). ``feature.straight`` adds the curvature the 40 m
    stencil of the 20 m grid picks up from the adjacent transition (see
    :func:`dbtools.rules.features.stencil_leak`)."""
    min_straight_m: float = 20.0
    """Minimum length of the entry (rows 1–2) and exit (rows 5–6) straights [m] (SPEC §5.3)."""

    # -- GIS heights (dbtools.rules.heights) -----------------------------------------------
    height_grade_warning_permille: float = 40.0
    """|grade| between two grid points above this: warning (``gis.height_grade``) [‰]; main
    adhesion lines stay below ~35 ‰."""
    height_grade_error_permille: float = 100.0
    """… above this: error — no adhesion railway is this steep (mountain lines reach 80 ‰) [‰]."""
    height_radius_warning_m: float = 1000.0
    """Vertical-curve radius below this: warning (``gis.height_curvature``) [m]; railways use
    2,000–4,000 m and more, survey noise of a few cm on a 20 m grid stays above ~5,000 m."""
    height_radius_error_m: float = 250.0
    """… below this: error — a spike of ~0.8 m on one point [m]."""

    # -- network topology (dbtools.rules.topology, dbtools.rules.balise_groups) --------------
    connection_gap_m: float = 1.0
    """Two joined track ends farther apart than this (``topology.gap``) [m]: survey noise is
    centimetres, a wrong end or a wrong track is metres."""
    km_jump_m: float = 1.0
    """Two tracks of one line whose km at the joined ends differ by more than this, without a
    ``km_breaks`` row for it (``topology.km_jump``) [m]."""
    switch_min_spacing_m: float = 5.0
    """Two switches joined by a track shorter than this overlap (``topology.switch_overlap``):
    shorter than any turnout's switch panel [m]."""
    length_tolerance_m: float = 2.0
    """``length_m`` vs the centreline's length: error beyond the larger of this [m] …"""
    length_tolerance_rel: float = 0.01
    """… and this fraction of the length (``topology.track_length``) [–]: the chords of a 20 m
    grid are shorter than the arc by L³/24R² (8 mm per step at R = 200 m) and a parallel
    track's length differs from its km difference by d/R (0.6 % at R = 300 m)."""
    crossover_angle_range: tuple[float, float] = (0.6, 1.25)
    """Largest angle of a crossover's chords to the main track / atan(1/n) must lie in this
    range (``topology.crossover_angle``) [–]: 20 m chords of the turnout curve read less than
    the frog angle (down to α/2 on the first chord, the straight between the frogs gives α
    itself); more than α is never right. It separates 1:9 from 1:15 and 1:6."""
    group_span_m: float = 30.0
    """Balises of one group identity farther apart than this (or on two tracks) stand at two
    places (``balise.group_duplicate``) [m]: the balises of a group are a few metres apart
    (SUBSET-036: ≥ 2.3 m, the group a few times that)."""

    # -- reporting -------------------------------------------------------------------------
    max_findings_per_rule: int = 1000
    """Findings listed per rule; the rest are summed up in one extra finding."""
