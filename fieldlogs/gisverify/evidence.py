"""Evidence for GIS verification: the trusted GPS fixes of recorded runs on a known track
[S001 §9(a), SPEC §6], and the ``gis verify`` driver (runs → evidence → statistics).

Per run the positioning pipeline (:func:`fieldlogs.pipeline.run.run_pipeline`) is replayed
against the DB under test. A fix is evidence only when

* the GPS unit trusts it (the 5/15/30 s RMS filter of :mod:`fieldlogs.pipeline.gps`);
* the pipeline's position at that moment is not *undetermined* and names a line and
  track — known from balises, or from a GPS up/down decision the pipeline accepted — or,
  on a network, a ``track_id`` (a station track, a crossover: the fix's ``track_id``
  column; such fixes are verified against the ``track_points`` grid,
  :mod:`dbtools.gis.verify.track_points`);
* the GPS decision in force, if any, does not name a different track (a disagreement
  means one of them is wrong: the fix is dropped, never guessed). An up/down decision
  speaks of a line's U/D/S tracks only: on a station track or a crossover (determined by
  the hypothesis engine) it neither contradicts nor confirms.

The track is therefore never inferred from the fix itself. The pipeline km at the fix time
(``km_ref_m``, linear between the two 100 ms cycles around it) is attached only where the
position is *determined*, its last absolute fix was a balise or a feature point (a GPS
initial position would compare the grid with itself) and its margin is at most
``max_km_margin_m``; elsewhere it is NaN and the fix only serves the lateral test. Each
fix also carries the pipeline's absolute-fix count (``km_ref_epoch``, :func:`fix_epochs`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from contextlib import closing
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.database import read_network
from dbtools.gis.verify.config import FIX_COLUMNS, KM_EPOCH_COLUMN, VerifyConfig
from dbtools.gis.verify.result import GisVerification
from dbtools.gis.verify.run import verify_fixes
from dbtools.gis.verify.track_points import verify_track_points
from dbtools.network import Network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.run import PipelineResult, run_pipeline
from fieldlogs.replay.discovery import discover_runs
from fieldlogs.replay.network import DbRef, load_network, open_db
from fieldlogs.replay.pool import replay
from fieldlogs.runs.handle import read_run
from schemas.enums import PositionState
from schemas.errors import InputError, TrainposError
from schemas.tables import TRACKS

#: Sources of the last absolute fix whose km may serve as the along-track reference.
KM_REF_SOURCES = ("balise", "feature")
#: Default largest pipeline margin for the along-track reference [m] (``[gis_verify]``).
MAX_KM_MARGIN_M: float = VerifyConfig().max_km_margin_m

Progress = Callable[[int, int, str], None]


@dataclass
class RunEvidence:
    """The evidence fixes of one run (``FIX_COLUMNS``) and why the others were left out."""

    run_id: str
    folder: str
    fixes: pd.DataFrame
    counts: dict[str, int] = field(default_factory=dict)
    """gps_fixes, trusted, no_position (undetermined or no track), track_conflict, used, with_km_ref."""


def fixes_from_result(result: PipelineResult, run_id: str, max_km_margin_m: float = MAX_KM_MARGIN_M) -> RunEvidence:
    """Select the evidence fixes of one pipeline result (module docstring)."""
    gps = result.gps
    empty = pd.DataFrame({c: pd.Series([], dtype=float) for c in FIX_COLUMNS})
    if gps is None or not len(gps.fixes) or not len(result.positions):
        return RunEvidence(run_id, "", empty, {"gps_fixes": 0, "trusted": 0, "used": 0})
    f = gps.fixes
    pos = result.positions
    t = f["t"].to_numpy(dtype=float)
    tc = pos["t"].to_numpy(dtype=float)
    n_c = tc.size
    i0 = np.clip(np.searchsorted(tc, t, side="right") - 1, 0, n_c - 1)
    i1 = np.minimum(i0 + 1, n_c - 1)
    state0, state1 = _text_at(pos["state"], i0), _text_at(pos["state"], i1)
    line, track = _text_at(pos["line_code"], i0), _text_at(pos["track"], i0)
    tid = _text_at(pos["track_id"], i0) if "track_id" in pos else np.full(len(i0), "", dtype=object)
    line1, track1 = _text_at(pos["line_code"], i1), _text_at(pos["track"], i1)
    trusted = f["trusted"].to_numpy(dtype=bool)
    before = t >= tc[0]
    named = ((line != "") & (track != "")) | (tid != "")  # a line track, or a network track off a line
    known = before & (state0 != PositionState.UNDETERMINED.value) & named
    dec_line, dec_track = _text(f["decided_line_code"]), _text(f["decided_track"])
    has_dec = (dec_line != "") & (dec_track != "")
    # an up/down decision speaks of a line's U/D/S tracks: it cannot contradict a station track
    # or a crossover the hypothesis engine determined (nor confirm it: that track is the engine's)
    line_track = np.isin(track, TRACKS)
    conflict = known & has_dec & line_track & ((dec_line != line) | (dec_track != track))
    use = trusted & known & ~conflict

    km = pos["km_m"].to_numpy(dtype=float)
    margin = pos["margin_m"].to_numpy(dtype=float)

    def km_ok(ix: np.ndarray, state: np.ndarray) -> np.ndarray:
        """The cycle's km may serve as the along-track reference (module docstring)."""
        source = _text_at(pos["last_fix_source"], ix)
        ok = (state == PositionState.DETERMINED.value) & np.isin(source, KM_REF_SOURCES)
        return np.asarray(ok & (margin[ix] <= max_km_margin_m) & np.isfinite(km[ix]), dtype=bool)

    dt = tc[i1] - tc[i0]
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(dt > 0, (t - tc[i0]) / dt, 0.0)
    km_ref = km[i0] + w * (km[i1] - km[i0])
    epoch = fix_epochs(margin)
    same = (line1 == line) & (track1 == track) & km_ok(i1, state1) & (epoch[i1] == epoch[i0])
    km_ref = np.where(km_ok(i0, state0) & same, km_ref, np.nan)

    sel = np.flatnonzero(use)
    fixes = pd.DataFrame(
        {
            "run_id": run_id,
            "t": t[sel],
            "lat": f["lat"].to_numpy(dtype=float)[sel],
            "lon": f["lon"].to_numpy(dtype=float)[sel],
            "line_code": line[sel].astype(str),
            "track": track[sel].astype(str),
            "track_id": tid[sel].astype(str),
            "km_ref_m": km_ref[sel],
            KM_EPOCH_COLUMN: epoch[i0[sel]],
        }
    )
    counts = {
        "gps_fixes": len(f),
        "trusted": int(trusted.sum()),
        "no_position": int((trusted & ~known).sum()),
        "track_conflict": int((trusted & conflict).sum()),
        "used": int(sel.size),
        "with_km_ref": int(np.isfinite(km_ref[sel]).sum()),
    }
    return RunEvidence(run_id, "", fixes, counts)


def fix_epochs(margin: np.ndarray) -> np.ndarray:
    """Per cycle, how many absolute fixes the pipeline had taken: its margin only ever
    drops at one (it grows with the travel otherwise). The pipeline's km error is reset
    there, so along-track residuals are compared within one epoch."""
    m = np.where(np.isfinite(margin), margin, np.inf)
    drops = np.concatenate([[0], (m[1:] < m[:-1] - 1e-9).astype(np.int64)])
    return np.cumsum(drops)


def _text(s: pd.Series) -> np.ndarray:
    """Strings as an object array, "" where missing (safe to compare)."""
    return np.asarray(s.to_numpy(dtype=object, na_value=""), dtype=object)


def _text_at(s: pd.Series, ix: np.ndarray) -> np.ndarray:
    """:func:`_text` of the rows ``ix`` only."""
    return _text(s.iloc[ix])


def run_evidence(
    folder: Path, network: Network, cfg: PipelineConfig | None = None, max_km_margin_m: float = MAX_KM_MARGIN_M
) -> RunEvidence:
    """Replay one run folder and select its evidence fixes. Any failure is an
    :class:`InputError` naming the folder (exit 2: a run that cannot be used is not a
    finding about the GIS)."""
    try:
        run = read_run(folder)
        result = run_pipeline(run, network, cfg or PipelineConfig())
    except TrainposError as exc:
        raise InputError(f"run cannot be used: {exc}", path=folder) from None
    except Exception as exc:  # a run the pipeline cannot replay
        raise InputError(f"run cannot be processed: {type(exc).__name__}: {exc}", path=folder) from exc
    ev = fixes_from_result(result, run.run_id, max_km_margin_m)
    ev.folder = str(folder)
    return ev


def evidence_one(folder: str, db: DbRef, cfg: PipelineConfig, max_km_margin_m: float) -> RunEvidence:
    """Replayer worker: one run against the DB of ``db`` (loaded once per worker process)."""
    return run_evidence(Path(folder), load_network(db), cfg, max_km_margin_m)


@dataclass
class Evidence:
    """Evidence of every run: fixes (``FIX_COLUMNS``, run ids made unique) and per-run counts."""

    fixes: pd.DataFrame
    runs: list[RunEvidence]

    def totals(self) -> dict[str, int]:
        keys = ("gps_fixes", "trusted", "no_position", "track_conflict", "used", "with_km_ref")
        return {k: sum(r.counts.get(k, 0) for r in self.runs) for k in keys}


def collect_evidence(
    run_dirs: Sequence[Path],
    db: Path,
    cfg: PipelineConfig | None = None,
    *,
    network: Network | None = None,
    max_km_margin_m: float = MAX_KM_MARGIN_M,
    workers: int | None = None,
    progress: Progress | None = None,
) -> Evidence:
    """Run the pipeline on every run folder (``workers`` processes) and gather the evidence.

    A run that cannot be read or replayed raises an :class:`InputError` naming the folder:
    a verification must not silently rest on fewer runs than it was given."""
    cfg = cfg or PipelineConfig()
    total = len(run_dirs)
    ref, _ = open_db(db, network)  # this process replays runs too: it keeps the network
    results: list[RunEvidence] = []
    tasks = [(str(p), (ref, cfg, max_km_margin_m)) for p in run_dirs]
    preload = ("fieldlogs.pipeline.run", "fieldlogs.pipeline.warm")
    outcomes = replay(evidence_one, tasks, workers=workers, ordered=True, preload=preload)
    with closing(outcomes):  # the first run that cannot be used stops the replay
        for out in outcomes:
            if out.value is None:  # its message names the folder, unless its worker died
                msg = out.error or "run cannot be used"
                raise InputError(msg, path=None if out.run in msg else out.run)
            results.append(out.value)
            if progress:
                progress(len(results), total, out.value.run_id)
    _unique_ids(results)
    frames = [r.fixes.assign(run_id=r.run_id) for r in results if len(r.fixes)]
    fixes = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=list(FIX_COLUMNS))
    return Evidence(fixes, results)


def _unique_ids(runs: list[RunEvidence]) -> None:
    """Two folders with the same run_id are two runs: suffix the folder name."""
    seen: dict[str, int] = {}
    for r in runs:
        seen[r.run_id] = seen.get(r.run_id, 0) + 1
    for r in runs:
        if seen[r.run_id] > 1:
            r.run_id = f"{r.run_id}@{Path(r.folder).name}"


def discover(roots: Iterable[Path]) -> list[Path]:
    """Run folders (holding run.json) at or below the given roots."""
    found = discover_runs(roots)
    if not found:
        raise InputError("no run folders (run.json) found", path=", ".join(str(r) for r in roots))
    return found


@dataclass
class VerifyReport:
    """What ``trainpos gis verify`` shows: the statistics plus where the evidence came from."""

    db: str
    db_version: str | None
    verification: GisVerification
    evidence: dict[str, int]
    runs: list[dict[str, Any]]
    network: Network
    track_points: GisVerification | None = None
    """The verification of the ``track_points`` grid (tracks off a line, per track_id;
    :mod:`dbtools.gis.verify.track_points`); None when the DB has none."""

    def to_dict(self) -> dict[str, Any]:
        out = {"db": self.db, "db_version": self.db_version, "evidence": self.evidence, "runs": self.runs}
        out.update(self.verification.to_dict())
        if self.track_points is not None:  # only a network DB has them: line-only output unchanged
            out["track_points"] = self.track_points.to_dict()
        return out


def verify_runs(
    db: Path,
    roots: Sequence[Path],
    *,
    pipeline: PipelineConfig | None = None,
    config: VerifyConfig | None = None,
    max_km_margin_m: float | None = None,
    workers: int | None = None,
    progress: Progress | None = None,
) -> VerifyReport:
    """``gis verify``: discover runs, replay them, select evidence (pipeline km as the
    along-track reference up to ``config.max_km_margin_m``; ``max_km_margin_m`` overrides
    it), verify the grid."""
    config = config or VerifyConfig()
    if max_km_margin_m is not None:
        config = replace(config, max_km_margin_m=max_km_margin_m)
    network = read_network(db)
    runs = discover(roots)
    ev = collect_evidence(
        runs,
        db,
        pipeline,
        network=network,
        max_km_margin_m=config.max_km_margin_m,
        workers=workers,
        progress=progress,
    )
    result = verify_fixes(network, ev.fixes, config)
    return VerifyReport(
        str(db),
        network.meta.get("db_version"),
        result,
        ev.totals(),
        [{"run_id": r.run_id, "folder": r.folder, **r.counts} for r in ev.runs],
        network,
        verify_track_points(network, ev.fixes, config),
    )
