"""The 2-frequency CW radar speed meter [S004], from raw IF samples to ground speed.

Two carriers f1, f2 = f1 + Δf alternate every T_pri (``radar_if`` stream, one row per
pair); each frequency's samples over T_epi are Fourier-transformed, every reflection gives
a Doppler line (relative speed V_m) whose f1/f2 phase difference gives its range R_m, and
eq. 2 turns the lines of a frame into the ground speed V_G despite the beam spread:

* ``framing`` — samples → (frames, N) arrays, N = T_epi/(2·T_pri);
* ``spectrum`` — window, FFT per frequency, CFAR noise floor, peaks, f1/f2 pairing,
  sub-bin Doppler, range R = c·Δφ/(4π·Δf);
* ``solve`` — eq. 1 / eq. 2 per frame, refinement, uncertainty, naive single-peak speed;
* ``speed`` — the whole run in blocks, frame status, CSV/JSON output;
* ``plots`` — radar vs wheel vs truth speed along a run, one frame's Doppler–range scatter.

The run.json ``radar`` block (``schemas.radar.RadarParams``) describes the radar; the
output columns are ``schemas.outputs.RADAR_SPEED``. Pure functions of their inputs; no
Python loop per frame.
"""
