"""``logs check`` of the raw radar IF samples (``radar_if``) against run.json's ``radar`` block.

* No ``radar`` block → an error: the samples cannot be processed (rate, frame length, λ).
* The samples are checked in FS (±1, ``schemas.logs.RADAR_IF``) after the declared
  ``full_scale``: I/full_scale, Q/full_scale — ADC counts with ``"full_scale": 2047`` are
  in range, and counts without it are named once with the declaration to add, not row by row.
* The I/Q convention: samples that fit S004 eq. 1 only conjugated
  (``fieldlogs.radar.convention``) → a warning naming the ``iq_convention`` to declare.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fieldlogs.radar.convention import check_convention, convention_finding
from fieldlogs.radar.framing import frame_samples
from fieldlogs.runs.handle import Run
from schemas.enums import Severity
from schemas.findings import Finding

SAMPLES = ("i1", "q1", "i2", "q2")


def scaled(run: Run, frame: pd.DataFrame) -> pd.DataFrame:
    """The samples in FS: divided by the declared ``full_scale`` (1 when none is declared)."""
    fs = run.radar.full_scale if run.radar is not None else 1.0
    if fs == 1.0:
        return frame
    out = frame.copy()
    for c in SAMPLES:
        out[c] = out[c] / fs
    return out


def _counts_finding(frame: pd.DataFrame, file: str) -> Finding | None:
    """Samples far beyond ±1 FS everywhere look like ADC counts: one finding, not one per row."""
    peak = float(np.nanmax(np.abs(frame[list(SAMPLES)].to_numpy(dtype=np.float64, na_value=np.nan)), initial=0.0))
    share = float((np.abs(frame[list(SAMPLES)].to_numpy(dtype=np.float64, na_value=np.nan)) > 1.0).mean())
    if peak <= 2.0 or share < 0.01:
        return None
    bits = int(np.ceil(np.log2(peak + 1.0))) + 1
    return Finding(
        "log.radar_full_scale",
        Severity.ERROR,
        "radar_if",
        f"radar_if samples reach {peak:g} ({share:.0%} of them beyond ±1 FS): ADC counts, not normalised to "
        f'the full scale — declare "full_scale" in run.json\'s radar block (the count at full scale, e.g. '
        f"{2 ** (bits - 1) - 1} for {bits}-bit samples)",
        file=file,
        column="radar.full_scale",
        value=peak,
        limit=1.0,
    )


def check_radar_if(run: Run, frame: pd.DataFrame, file: str) -> tuple[pd.DataFrame, list[Finding]]:
    """(the columns for the value checks — the samples in FS, or only ``t`` when they are ADC
    counts without a declared full scale —, the findings of this module)."""
    if run.raw_json.get("radar") is None:
        return frame, [
            Finding(
                "log.radar_params",
                Severity.ERROR,
                "radar_if",
                "raw radar samples need the radar's parameters: run.json has no 'radar' block "
                "(f0_hz, delta_f_hz, t_pri_s, t_epi_s, height_m, depression_deg, beam_elev_deg, beam_az_deg); "
                "the rate is checked against Table 1's 1/(2·50 µs)",
                file=file,
                column="radar",
            )
        ]
    fs = scaled(run, frame)
    counts = _counts_finding(fs, file)
    if counts is not None:  # one finding instead of one per row; t is still checked
        return fs[["t"]], [counts]
    if run.radar is None:  # the block's own findings say why
        return fs, []
    t = fs["t"].to_numpy(dtype=np.float64, na_value=np.nan)
    i1, q1, i2, q2 = (frame[c].to_numpy(dtype=np.float32, na_value=np.nan) for c in SAMPLES)
    found = convention_finding(check_convention(frame_samples(t, i1, q1, i2, q2, run.radar), run.radar), file)
    return fs, [found] if found is not None else []
