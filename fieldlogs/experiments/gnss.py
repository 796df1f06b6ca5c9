"""Seeded simulated experiments of the track-constrained positioning (bench and tests) [S002].

One case: a constellation (seeded orbits, clocks and start time anywhere in the week), the
synthetic 3-D track of ``fieldlogs.simulate.gnss.scenario``, a run with stops, two receivers with antennas 8 m
ahead of and behind the vehicle's centre at 3.8 m above the rail (different clocks), the
sky mask of the paper's experiment (west half blocked), and optionally D-GPS corrections and
one faulty satellite (a step or a slow ramp on a satellite the clean solution uses, from
mid-run, in every receiver: a satellite fault).

The prior (the pipeline's own estimate, phase 2: tachometer between balises) is simulated as
s_true + a run bias N(0, 1.5 m) + a random walk of 0.05 m/√s, declared σ = 5 m.

Metrics per receiver-epoch: constrained availability (status ok and the antenna-distance
check passed), unconstrained availability (≥ 4 satellites, PDOP ≤ 6), along-track error
s − s_true of available epochs and whether it exceeds the stated uncertainty; in fault cases
the epochs after onset with the faulty satellite among ≥ 3 usable ones, whether it is excluded
(by the w/χ² tests, for no on-track solution or by the code-carrier divergence monitor; or the
epoch refused) from the 2nd epoch on where its bias has reached the row's minimal
detectable bias (a 50 m step at once unless the geometry cannot see 50 m; a ramp when it has
grown to it), and the error against the uncertainty meanwhile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import WEEK_S
from fieldlogs.gnss.observables import FLAG_CODE_CARRIER, FLAG_EXCLUDED, FLAG_NO_TRACK_SOLUTION
from fieldlogs.gnss.position import PositionConfig, PositionResult, position_run
from fieldlogs.gnss.skymask import load_mask
from fieldlogs.gnss.track import Antenna
from fieldlogs.simulate.gnss.constellation import constellation_nav
from fieldlogs.simulate.gnss.observations import (
    Corridor,
    ErrorSpec,
    ReceiverSpec,
    Simulated,
    dgps_corrections,
    inject_fault,
    simulate,
    with_sat_errors,
)
from fieldlogs.simulate.gnss.scenario import SyntheticTrack, mixed_corridor, run_profile, synthetic_track, trajectory

ANTENNAS = {"rx1": Antenna(8.0, 0.0, 3.8), "rx2": Antenna(-8.0, 0.0, 3.8)}


@dataclass(frozen=True)
class CaseSpec:
    """One simulated case (module docstring)."""

    seed: int
    systems: tuple[str, ...] = ("G",)
    duration_s: float = 600.0
    sky: str = "west-half"
    dgps: bool = False
    corridor: str = "open"
    fault: str | None = None
    """None, 'step' (50 m) or 'ramp' (0.2 m/s)."""
    prior_sigma_m: float = 5.0
    use_prior: bool = True
    """False: no prior at all (coarse search along the whole track, no prior in the tests)."""
    elevation_mask_deg: float = 10.0
    sat_errors: bool = False
    """Broadcast orbit and clock errors in the truth (``simulate.with_sat_errors``), as an SBAS run has them."""
    sbas: bool = False
    """Write an SBAS stream for the run (``fieldlogs.simulate.gnss.sbas_stream``, with ``sat_errors``)
    and position with it."""
    two_geos: bool = False
    """With ``sbas``: two GEOs (``two_geo_stream``) instead of PRN 137 alone."""


@dataclass
class CaseResult:
    epochs: pd.DataFrame
    fault_sat: str | None
    fault_t0: float


_TRACK: list[SyntheticTrack] = []


def _track() -> SyntheticTrack:
    if not _TRACK:
        _TRACK.append(synthetic_track())
    return _TRACK[0]


def _simulate(spec: CaseSpec) -> tuple[Simulated, np.ndarray, np.ndarray, pd.DataFrame | None, pd.DataFrame]:
    """The run, its truth times and s, the D-GPS corrections or SBAS stream, the prior."""
    rng = np.random.default_rng(spec.seed)
    tr = _track()
    t0 = 2300 * WEEK_S + float(np.floor(rng.uniform(0.0, WEEK_S)))
    s = run_profile(
        tr.truth.length_m, spec.duration_s, 1.0, float(rng.uniform(15.0, 30.0)), float(rng.uniform(0.0, 4000.0)), 3000.0
    )
    traj = trajectory(tr, s, t0, 1.0)
    nav = constellation_nav(t0, t0 + spec.duration_s, seed=spec.seed)
    rx = [
        ReceiverSpec("rx1", 8.0, 0.0, 3.8, float(rng.uniform(-5e-4, 5e-4)), float(rng.normal(0, 2e-8))),
        ReceiverSpec("rx2", -8.0, 0.0, 3.8, float(rng.uniform(-5e-4, 5e-4)), float(rng.normal(0, 2e-8))),
    ]
    corridor = mixed_corridor(tr.truth.length_m, spec.seed) if spec.corridor == "mixed" else Corridor()
    errors = with_sat_errors(ErrorSpec()) if (spec.sat_errors or spec.sbas) else None
    sim = simulate(traj, nav, rx, corridor, seed=spec.seed + 1_000_003, errors=errors, systems=spec.systems)
    corr = dgps_corrections(sim, seed=spec.seed + 7) if spec.dgps else None
    if spec.sbas:
        from fieldlogs.simulate.gnss.sbas_stream import sbas_stream

        corr = sbas_stream(sim, seed=spec.seed + 11, lead_s=120.0)
        if spec.two_geos:
            corr = two_geo_stream(corr, sbas_stream(sim, seed=spec.seed + 13, geo=129, lead_s=60.0))
    walk = np.cumsum(rng.normal(0.0, 0.05, s.size))
    prior = pd.DataFrame({"t": traj.t, "s_m": s + rng.normal(0.0, 1.5) + walk, "sigma_m": spec.prior_sigma_m})
    return sim, traj.t, s, corr, prior


#: ``two_geo_stream``: PRN 137 silent over these run seconds, PRN 129's MT 0 at this one.
SILENT_137_S = (200.0, 400.0)
MT0_129_S = 450.0


def two_geo_stream(s137: pd.DataFrame, s129: pd.DataFrame) -> pd.DataFrame:
    """Both GEOs' streams (each with its own network error; 129's heard from 60 s before the
    run, 137's from 120 s, so 137 is complete first and taken), PRN 137 silent over
    ``SILENT_137_S`` and PRN 129's message at ``MT0_129_S`` replaced by an MT 0, in time order:
    137 until it times out (18 s into the silence), then 129 (kept when 137 is back), then 137
    again from 129's MT 0 (``sbas.geo_select``)."""
    from fieldlogs.simulate.gnss import sbas_encode as enc

    t = s137["t"].to_numpy(dtype=float)
    a = s137[(t < SILENT_137_S[0]) | (t >= SILENT_137_S[1])]
    b = s129.copy()
    k = int(np.argmin(np.abs(b["t"].to_numpy(dtype=float) - MT0_129_S)))
    pre = {0x53: 0, 0x9A: 1, 0xC6: 2}[bytes.fromhex(str(b["message_hex"].iloc[k]))[0]]
    mt0 = enc.mt0(pre)  # the preamble of the message it replaces
    b["msg_type"] = np.where(np.arange(len(b)) == k, 0, b["msg_type"].to_numpy())
    b["message_hex"] = np.where(np.arange(len(b)) == k, mt0.hex().upper(), b["message_hex"].to_numpy(dtype=object))
    out = pd.concat([a, b], ignore_index=True)
    return out.sort_values(["gnss_time_s", "prn"], kind="stable").reset_index(drop=True)


def _solve(
    sim: Simulated, obs: pd.DataFrame, spec: CaseSpec, corr: pd.DataFrame | None, prior: pd.DataFrame
) -> PositionResult:
    sbas = None
    if spec.sbas:
        from fieldlogs.gnss.sbas import SbasCorrections

        sbas, corr = SbasCorrections.from_stream(corr), None
    return position_run(
        obs,
        sim.nav,
        _track().grid,
        ANTENNAS,
        iono=sim.iono,
        corrections=corr,
        sky_mask=load_mask(spec.sky),
        prior=prior if spec.use_prior else None,
        cfg=PositionConfig(systems=spec.systems, elevation_mask_deg=spec.elevation_mask_deg),
        sbas=sbas,
    )


def _fault_sat(res: PositionResult, t_from: float) -> str | None:
    """The satellite the clean solution uses most after ``t_from`` (receiver rx1)."""
    ep = res.observations
    sel = (ep.receiver == "rx1") & (ep.t_run >= t_from)
    used = ep.sat[sel][ep.usable[sel]]
    if used.size == 0:
        return None
    names, counts = np.unique(used, return_counts=True)
    return str(names[np.argmax(counts)])


def run_case(spec: CaseSpec) -> CaseResult:
    """Simulate and position one case; per receiver-epoch metrics (module docstring)."""
    sim, t, s_true, corr, prior = _simulate(spec)
    res = _solve(sim, sim.obs, spec, corr, prior)
    fault_sat, t_f = None, float(t[0] + spec.duration_s / 2.0)
    if spec.fault is not None:
        fault_sat = _fault_sat(res, t_f)
        if fault_sat is not None:
            obs = inject_fault(
                sim.obs,
                fault_sat,
                t_f,
                step_m=50.0 if spec.fault == "step" else 0.0,
                ramp_mps=0.2 if spec.fault == "ramp" else 0.0,
            )
            res = _solve(sim, obs, spec, corr, prior)
    tb = res.epochs.copy()
    tb["s_true_m"] = np.interp(tb["t"].to_numpy(float), t, s_true)
    tb["err_m"] = tb["s_m"] - tb["s_true_m"]
    tb["ok"] = tb["available"] & tb["antenna_distance_ok"]
    tb["exceeds"] = tb["ok"] & (tb["err_m"].abs() > tb["uncertainty_m"])
    tb["n_divergence"] = ((res.observations.flags & FLAG_CODE_CARRIER) > 0).sum(axis=1)
    if fault_sat is not None:
        ep = res.observations
        row = ep.sat == fault_sat
        tb["fault_present"] = (row & ep.present).any(axis=1) & (tb["t"].to_numpy() >= t_f)
        # integrity rejections: FDE exclusion, no on-track solution, code-carrier divergence (a
        # rejected row would have been usable but for the rejection: its other flags are clear)
        rej = FLAG_EXCLUDED | FLAG_NO_TRACK_SOLUTION | FLAG_CODE_CARRIER
        rejected = ep.present & ((ep.flags & rej) > 0) & ((ep.flags & ~rej) == 0)
        n_cand = (ep.usable | rejected).sum(axis=1)
        tb["fault_usable3"] = tb["fault_present"] & (n_cand >= 3) & (row & (ep.usable | rejected)).any(axis=1)
        tb["fault_excluded"] = (row & rejected).any(axis=1)
        tb["fault_epoch"] = np.round(tb["t"].to_numpy() - t_f).astype(int)
        tb["fault_bias_m"] = np.where(tb["fault_present"], 50.0 if spec.fault == "step" else 0.2 * (tb["t"] - t_f), 0.0)
        tb["fault_mdb_m"] = np.nanmin(np.where(row, res.mdb_m, np.inf), axis=1)
        detectable = tb["fault_present"] & ((tb["fault_bias_m"] >= tb["fault_mdb_m"]) | tb["fault_excluded"])
        first = tb["t"].where(detectable).groupby(tb["receiver"]).transform("min")
        tb["fault_detectable_epoch"] = np.round(tb["t"] - first)
    return CaseResult(tb, fault_sat, t_f)


def summarise(results: list[CaseResult]) -> dict[str, float]:
    """Headline statistics over cases (module docstring)."""
    tb = pd.concat([r.epochs for r in results], ignore_index=True)
    ok = tb["ok"]
    err = tb.loc[ok, "err_m"].abs()
    out = {
        "epochs": float(len(tb)),
        "constrained_availability": float(ok.mean()),
        "unconstrained_availability": float(tb["lsq_available"].mean()),
        "median_abs_err_m": float(err.median()) if err.size else np.nan,
        "p99_abs_err_m": float(np.percentile(err, 99)) if err.size else np.nan,
        "max_abs_err_m": float(err.max()) if err.size else np.nan,
        "exceed_fraction": float(tb["exceeds"].sum() / max(int(ok.sum()), 1)),
        "median_uncertainty_m": float(tb.loc[ok, "uncertainty_m"].median()) if err.size else np.nan,
    }
    if "fault_present" in tb.columns:
        f = tb[tb["fault_present"].fillna(False).astype(bool) & tb["fault_usable3"].fillna(False).astype(bool)]
        late = f[f["fault_detectable_epoch"] >= 1]
        missed = late["ok"] & ~late["fault_excluded"].astype(bool) & (late["fault_bias_m"] >= late["fault_mdb_m"])
        out["fault_epochs"] = float(len(f))
        out["fault_not_excluded_after_2_epochs"] = float(missed.mean()) if len(late) else np.nan
        out["fault_exceed_fraction"] = float((f["exceeds"]).sum() / max(int(f["ok"].sum()), 1))
        out["fault_availability"] = float(f["ok"].mean()) if len(f) else np.nan
        ex = f[f["fault_excluded"].astype(bool)]
        out["fault_bias_at_exclusion_m"] = (
            float(ex.groupby("receiver")["fault_bias_m"].min().median()) if len(ex) else np.nan
        )
    return out
