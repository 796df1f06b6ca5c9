"""The result of a decoded track HMM: every fix's projection, the path and the summary
(the definitions: :mod:`fieldlogs.trackmatch.match`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from fieldlogs.trackmatch.result import FIX_COLUMNS, PATH_COLUMNS, Hmm, TrackMatch

if TYPE_CHECKING:
    from dbtools.gis.track_candidates import Candidates
    from dbtools.gis.track_segments import TrackGeometry
    from fieldlogs.trackmatch.routes import Routes

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
Decoded = tuple[I64, F64, npt.NDArray[np.bool_], F64, F64]


def _fix_frame(
    geo: TrackGeometry, c: Candidates, hmm: Hmm, dec: Decoded, t: F64, lat: F64, lon: F64, status: Any
) -> pd.DataFrame:
    best, gamma = dec[0], dec[1]
    n = len(t)
    chosen = np.full(n, -1, dtype=np.int64)
    prob = np.full(n, np.nan)
    if len(best):
        chosen[hmm.steps] = hmm.cand[best]
        # P(fix on the chosen track) = γ of its one candidate on that track
        prob[hmm.steps] = gamma[best]
    has = chosen >= 0
    k = np.where(has, chosen, 0)
    ids = np.asarray(geo.track_ids, dtype=object)

    def pick(v: F64) -> F64:
        return np.where(has, v[k], np.nan) if len(v) else np.full(n, np.nan)

    return pd.DataFrame(
        {
            "t": t,
            "lat": lat,
            "lon": lon,
            "status": status,
            "track_id": _names(ids, c.track, k, has),
            "offset_m": pick(c.offset_m),
            "distance_m": pick(c.pos_m),
            "km_m": pick(c.km_m),
            "probability": prob,
        },
        columns=list(FIX_COLUMNS),
    )


def _names(ids: npt.NDArray[np.object_], track: I64, k: I64, has: npt.NDArray[np.bool_]) -> npt.NDArray[np.object_]:
    """Track id of each fix's chosen candidate, None where it has none."""
    out = np.full(len(k), None, dtype=object)
    out[has] = ids[track[k[has]]]
    return out


def _xi(hmm: Hmm, dec: Decoded, k: int, logz: float) -> tuple[float, int]:
    """Posterior of the chosen transition into step k and the ends code it takes."""
    best, _, _, alpha, beta = dec
    i, j = int(best[k - 1]), int(best[k])
    m = int(hmm.coff[k + 1] - hmm.coff[k])
    pair = int(hmm.poff[k]) + (i - int(hmm.coff[k - 1])) * m + (j - int(hmm.coff[k]))
    v = min(1.0, float(np.exp(alpha[i] + hmm.logt[pair] + hmm.loge[j] + beta[j] - logz)))
    return v, int(hmm.ends[pair])


def _rows(geo: TrackGeometry, routes: Routes, c: Candidates, hmm: Hmm, dec: Decoded, t: F64) -> list[list[Any]]:
    """Path rows [chain, track index, probabilities, t_from, t_to, fixes] before merging."""
    best, gamma, start, alpha, _ = dec
    rows: list[list[Any]] = []
    chain = -1
    logz = 0.0
    for k in range(len(best)):
        trk = int(c.track[hmm.cand[best[k]]])
        tk = float(t[hmm.steps[k]])
        if start[k]:
            chain += 1
            last = k
            while last + 1 < len(best) and not start[last + 1]:
                last += 1
            a = alpha[hmm.coff[last] : hmm.coff[last + 1]]
            mx = float(np.max(a))
            logz = mx + float(np.log(np.sum(np.exp(a - mx))))
        elif rows[-1][1] != trk:
            xi, ends = _xi(hmm, dec, k, logz)
            prev, t_prev = rows[-1][1], rows[-1][4]
            for p in routes.passed(prev, ends // 2, trk, ends % 2):
                rows.append([chain, p, [xi], t_prev, tk, 0])
        if rows and rows[-1][0] == chain and rows[-1][1] == trk and rows[-1][5] > 0:
            rows[-1][2].append(float(gamma[best[k]]))
            rows[-1][4] = tk
            rows[-1][5] += 1
        else:
            rows.append([chain, trk, [float(gamma[best[k]])], tk, tk, 1])
    return rows


def assemble(
    net: Network,
    geo: TrackGeometry,
    routes: Routes,
    c: Candidates,
    hmm: Hmm,
    dec: Decoded,
    t: F64,
    lat: F64,
    lon: F64,
    status: Any,
) -> TrackMatch:
    """Fix frame, path frame and summary of a decoded HMM."""
    del net
    fixes = _fix_frame(geo, c, hmm, dec, t, lat, lon, status)
    rows = _rows(geo, routes, c, hmm, dec, t)
    path = pd.DataFrame(
        [[r[0], geo.track_ids[r[1]], float(np.mean(r[2])), r[3], r[4], r[5]] for r in rows], columns=list(PATH_COLUMNS)
    )
    off = np.abs(fixes["offset_m"].to_numpy(float))
    off = off[np.isfinite(off)]
    counts = fixes["status"].value_counts()
    summary: dict[str, Any] = {
        "fixes": len(fixes),
        **{str(k): int(counts.get(k, 0)) for k in ("matched", "no_candidate", "outlier", "no_position")},
        "chains": int(path["chain"].max()) + 1 if len(path) else 0,
        "path_tracks": len(path),
        "mean_abs_offset_m": float(off.mean()) if len(off) else None,
        "max_abs_offset_m": float(off.max()) if len(off) else None,
    }
    return TrackMatch(path, fixes, summary)
