"""Slip/slide detection and inertial correction of the pulse odometry [S000 §3.1, SPEC §5.1].

:func:`~.correct.correct_odometry` runs pure stages on the 100 ms cycle arrays of :class:`Cycles`; each
is a function of the previous stages' frozen results and the config:

1. :func:`~.streams.align_streams` → :class:`~.streams.AlignedStreams`: travel frame,
   pulse delay (searched), the filter K on a_x and A_p, the gyro pitch u.
1b. With a ground speed (the radar [S004]): :func:`~.ground.align_ground` →
   :class:`~.ground.GroundSpeed`: the direction check, delayed onto the IMU, 1 s means.
2. :func:`~.detection.detect` → :class:`~.detection.Detections`: eq. 1, the gyro bias,
   the grade-compensated residual, the ground-speed criterion, onsets, the start-point
   condition.
3. :func:`~.episodes.find_episodes` → :class:`~.episodes.Episode` records: start point
   (:mod:`.start_point`), attitude at i0 and integration (:mod:`.integration`), with a
   ground speed the fused speed and its budget (:mod:`.fusion`), re-adhesion, speed
   update, re-opening and echoes.
4. :func:`~.watch.watch_failsafe` (with a ground speed :func:`~.watch.watch_fused`) →
   :class:`~.watch.Watch` of each fail-safe episode, made as stage 3 ends it
   (``Episode.watch``).
5. :func:`~.assembly.assemble` → :class:`Odometry` (d, v, slipping, allowance, the public
   :class:`SlipEpisode` list, and ``diagnostics`` — the internals, for tests and bench).
6. With a ground speed: :func:`~.ground_products.ground_products`: the speed at low speed
   and standstill, the wheel calibration (and the scale, if set), ``Odometry.ground``.

Detection, jerks, smoothing and the start-point search are vectorised over the whole run;
only the (rare) episodes are visited in a Python loop, each integrated with ``np.cumsum``
over at most ``max_correction_s`` + ``failsafe_watch_s`` of cycles (with a ground speed
``ground_max_correction_s`` + the watch, and its Kalman filter a loop over those cycles).
Without a ground speed stages 1b and 6 do not run and the others take their S000 path.

Frames
    Travel frame: x along travel, y left, z up (SPEC §4.1), the body frame turned 180°
    about z when the cab is reversed (``ax, ay, wx, wy`` change sign). Pitch θ nose-up in
    the travel direction (the gradient climbed), roll ψ positive with the left side up.
    Aligned index k holds pulse and IMU data of the same instant (pulses delayed D
    cycles); outputs are on the cycle grid of ``cycles.t``.

Equations (where they are computed)
    * eq. 1 detection |a_x − A_p| > Ta — :mod:`.detection`;
    * eq. 3 pitch θ0 = arcsin((a_x0 − A_p0)/G) and eq. 11 roll ψ0 =
      arctan((a_y0 − v0·ω_z0)/a_z0) at the start point — :mod:`.integration`;
    * eqs. 4, 5/12, 6 attitude: θ = θ0 + ∫θ̇ dt with θ̇ = −wy·cosψ + wz·sinψ (eq. 12 in this
      frame), ψ = ψ0 + ∫ω_x dt — :mod:`.integration` (and over the whole run in
      :mod:`.streams`);
    * eq. 2 correction A_x = a_x − G·sinθ, integrated to speed and distance —
      :mod:`.integration`, :mod:`.assembly`;
    * eq. 13 error budget Δd = ½·Δa·t² — :mod:`.assembly` (``slip_budget_m``); with a
      ground speed the budget of :mod:`.fusion`.

Where the code departs from the papers (each module says why; measurements in
bench/NOTES.md, "Odometry")
    * eq. 12's third term −k·ω_x·sinψ is left out: it has no counterpart in rigid-body
      kinematics (an empirical term of the papers' installation).
    * Re-adhesion: the 1 s mean inertial and pulse speeds agreeing within ε + β·t for
      ``readhesion_hold_s``, instead of the per-cycle pulse speed within β·t and
      |a_x − A_p| ≤ Ta, which both fail for shallow slips.
    * A second, grade-compensated residual criterion finds the shallow slips that Ta (which
      must exceed the steepest gradient's G·sinθ) cannot.
    * The pulse delay is searched in the run (the residual needs the true delay, the SPEC's
      300 ms is only the installation value); a 1 s mean precedes the 3 s moving average
      (pulse quantisation).
    * The gyro pitch-rate bias is estimated while adhering and removed (the main error of
      long corrections otherwise).
    * The re-adhesion speed update closes each re-adhered correction on the measured speed
      difference.
    * The fail-safe watch keeps the margin growing while the wheel may still be slipping
      after a fail-safe.
    * A correction whose start point did not adhere (θ̄ clipped, or no start point found and
      the look-back point flagged) fails safe at its start; a detection after a fail-safe
      that no correction can follow gets a watch of its own and makes the position
      uncertain again (:mod:`.episodes`, :mod:`fieldlogs.pipeline.aids.failsafe`).
    * θ0 uses a least-squares A_p0 over the filter window (pulse quantisation), residual
      detections have their own look-back point and the lobe rule.
    * With a ground speed (the radar [S004]; S000 has none): a third detection criterion,
      corrections fused with it by their variances (Kalman filter and smoother) instead of
      inertial bridging alone, re-adhesion and the fail-safe watch tested on it, an error
      budget from its σ instead of eq. 13 (the fail-safe when that budget reaches eq. 13's
      at ``max_correction_s``), the speed at low speed and standstill from it, and a wheel
      calibration (:mod:`.ground`, :mod:`.fusion`, :mod:`.ground_products`).

NaN policy: missing IMU cycles are bridged by linear interpolation for the integration; the
moving averages use what exists; no detection where a smoothed value is missing; missing
pulse distances and speeds count as 0.
"""
