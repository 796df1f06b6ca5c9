"""GIS grid verification from traversed trajectories [S001 §9(a), SPEC §6].

Input: GPS fixes whose track is *known* (from balises or the GPS up/down decision, never
guessed — :mod:`fieldlogs.gisverify.evidence` selects them), one row per fix with the columns of
:data:`FIX_COLUMNS`. Everything below is vectorised over fixes (no Python loop per fix or
per cell; one small loop per *defect*).

**1. Map-matching.** Each fix is matched exactly to the nearest segment of its known
track (:meth:`~dbtools.gis.matching.TrackIndex.match_xy`, within ``max_offset_m``): km
``k_i`` and signed lateral offset ``o_i`` (positive left of increasing km). Its *cell* is
the grid segment [km_j, km_j+1) that holds k_i (20 m). The along-track residual
``r_i = k_i − km_ref_i`` compares the GPS km with the pipeline's balise/feature-corrected
km where that is known well enough (``km_ref_m``; NaN otherwise).

**2. The run is the unit.** D-GPS error is Gauss–Markov with a correlation time of
minutes: over one cell (about one second at line speed), and over a few hundred metres,
it is a single draw per run. Fixes of one run in one cell are therefore not independent
evidence; they are averaged first. For cell c with runs r = 1..k_c::

    ō_rc = mean of run r's offsets in c
    m_c  = mean_r ō_rc,   s_c = sd_r ō_rc (ddof 1, the between-run spread),   se_c = s_c / √k_c

**3. Test.** H0: the cell's GIS centreline is right (μ_c = 0). The between-run spread
is a property of the receivers, not of the cell, so it is also pooled over the track
(``s_pool² = Σ(k_c − 1)s_c² / Σ(k_c − 1)``); the test uses ``s = max(s_c, s_pool)`` —
a cell's own spread only where it is larger (local multipath) — because with a handful
of runs ``s_c`` alone is often small by chance, and a small spread times a moderate mean
would then pass for a defect. ``t_c = m_c / (s/√k_c)`` against Student's t with k_c − 1
degrees of freedom for the own spread, (runs on the track − 1) for the pooled one (a
conservative count: neighbouring cells share the same runs' errors); ``p_c`` two-sided.
Over all *testable* cells the p-values are corrected for multiple testing —
Benjamini–Hochberg (false-discovery rate, default; valid under the positive dependence of
neighbouring cells) or Bonferroni (family-wise) — giving ``q_c``. A cell is a **defect
cell** when ``q_c ≤ alpha`` *and* ``|m_c| ≥ min_shift_m`` (significance alone is not
enough: with hundreds of runs a few centimetres become significant but are not worth a
DB change; the simulator's spline-vs-chord difference on 300 m curves is ~0.1 m).

**4. Status.** A cell is *unverified* — never "good" — when it has fewer than
``min_runs`` runs or ``min_fixes`` fixes ("evidence"), or when it is not a defect but its
95 % confidence interval ``|m_c| + t₀.₉₇₅·se_c`` reaches beyond ``tolerance_m``
("inconclusive": too noisy to say the centreline is right to within the tolerance — the
cells either side of a displaced stretch, which see half of it, usually land here).
Otherwise it is *verified*. Cells of the grid without any fix are unverified too; they
appear in the coverage only.

**5. Defects.** Defect cells of one track with the same sign of shift are merged when at
most ``merge_gap_cells`` cells lie between them (never across a kilometrage break). Per
defect the runs are again the unit: the per-run mean over the defect's (run, cell) means
gives a t-test p-value as in 3. The **shift** is estimated differently: each run's mean
inside the defect minus its *own* mean offset over ``background_m`` either side (the cell
next to the defect and other defects skipped). The D-GPS error of a run barely changes
over the seconds between the two (σ·√(2(1 − e^(−Δt/τ))) ≈ 0.3 m for 15 s at τ = 180 s
against 0.75 m), so the difference removes most of it: the shift's error drops from
σ/√runs to about 0.3 m/√runs (``background_m`` column: what was removed).

**6. Proposed correction.** The lateral error of the grid is taken as piecewise linear
between grid points (that is how the DB interpolates the track): a fix at fraction u of
segment j sees ``(1 − u)·e_j + u·e_{j+1}``. Per defect the point shifts e_j of the
defect's points are the weighted least-squares solution over the background-corrected
offsets (as in 5) of the fixes of its cells and of the one cell on each side (points
outside fixed at 0; each (run, cell) has total weight 1, as in 2), with a tiny ridge and
a total-variation penalty ``smooth``·Σ|Δe| (iteratively reweighted least squares on the
tridiagonal system), which flattens noise while keeping the ends of a displaced stretch
sharp; the levels of the resulting segments are then refitted without the penalty (no
shrinkage). Three Huber re-weightings (residuals beyond 2 robust sd) keep a multipath
burst that passed the trust filter from bending the fit. Points whose estimate reaches ``min_move_m`` are moved that far
perpendicular to the track (tangent from the grid points two either side, in the plane
zone of :class:`Projector`), to the left for a positive shift — where the fixes say the
track really is.

**7. Along-track residual.** Per cell the run-level mean and spread of ``r_i`` are
reported (per cell not tested: the pipeline km carries its own error, up to its margin,
correlated within a run — only cycles with a small margin provide ``km_ref_m``; the scan of
8 tests it over windows).

**8. The scan** (:mod:`~dbtools.gis.verify.scan`, ``scan`` on). With one 1 Hz fix per pass
per cell a handful of runs cannot test a cell; neighbouring cells are pooled into windows
of ``scan_windows_m`` (100–500 m): per run its mean offset in the window minus its own mean
offset over ``background_m`` either side (the slow GPS error removed, as in 5), weighted by
how little that error can drift in between; the runs' contrasts are t-tested with the
variance moderated per window length [Smyth 2004], Bonferroni (``scan_correction``) over
every window of every track. The windows it selects make their cells defect cells (merged
with those of 3 as in 5, so the shift, the proposal of 6 and the status follow the pooled
defect); cells it does not select keep the status of 4 — a window that tested clean never
makes an unverified cell verified. The same scan on the along-track residual of 7, with the
run-epoch as the unit, gives the ``km_defects`` (reported, not proposed).

**Keys.** Every row of the result names its network track, ``track_id``: on a line grid the
declared track whose km span holds the row's first cell (:func:`dbtools.topology.grid_track_ids`),
else the implied ``LINE:TRACK``; ``line_code`` and ``track`` are kept as its names. The tracks
off a line (``track_points``) are verified by :mod:`~dbtools.gis.verify.track_points`, their
rows keyed the same way with ``pos_*`` (metres along the track) in the place of ``km_*``.

Modules: :mod:`~dbtools.gis.verify.config` (thresholds, column sets),
:mod:`~dbtools.gis.verify.cells` (steps 1–4, 7 and the coverage),
:mod:`~dbtools.gis.verify.defects` (step 5 and the scan's defects),
:mod:`~dbtools.gis.verify.proposal` (step 6), :mod:`~dbtools.gis.verify.scan` (step 8),
:mod:`~dbtools.gis.verify.result` (the result and its JSON shape);
:func:`dbtools.gis.verify.run.verify_fixes` runs them (this package file imports nothing:
the thresholds of :mod:`~dbtools.gis.verify.config` are read without numpy or scipy).
All plane work is in the network's one projection (:mod:`dbtools.gis.index`).
Measured recall and false-defect rates are in ``bench/NOTES.md`` ("GIS verification").
"""
