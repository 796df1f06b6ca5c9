"""UBX ESF-RAW / ESF-MEAS ↔ ``imu`` and ``tacho``.

Samples (``data`` X4: bits 0–23 value, 24–29 type) are gathered from every frame at once:
ESF-RAW carries (data, sensor time tag) pairs, ESF-MEAS one time tag and ``numMeas``
values. Types: 14/13/5 gyro x/y/z (deg/s · 2⁻¹², signed 24 bit), 16/17/18 accelerometer
x/y/z (m/s² · 2⁻¹⁰), 10 single tick, else 8/9/6/7 rear-left/rear-right/front-left/
front-right wheel ticks (bits 0–22 count, bit 23 direction; the count is unwrapped modulo
2²³ into a cumulative, never-decreasing ``pulses``; the direction is left to ``cab``).

u-blox sensor axes are x forward, y right, z down; the body frame (SPEC §4.1) is x
forward, y left, z up, so ay, az, wy and wz change sign. The vehicle file's residual
mounting rotation is recorded in run.json, not applied here.

Time: sensor time tags are the recorder's own clock. Each NAV-PVT (else RAWX epoch) is
paired with the time tag of the last ESF sample before it in the file, the tick length is
taken as the u-blox one (1 ms, 39.0625 µs, 1 µs) nearest the fitted rate, and the clock
model of ``timebase.fit_clock`` maps every tag to GPS time; its drift and residual go to
the provenance.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from fieldlogs.recorders.common import Decoded
from fieldlogs.recorders.timebase import fit_clock
from schemas.errors import InputError

if TYPE_CHECKING:
    from fieldlogs.recorders.ubx_frames import Frames

GYRO = {14: "wx", 13: "wy", 5: "wz"}
ACC = {16: "ax", 17: "ay", 18: "az"}
TICK_TYPES = (10, 8, 9, 6, 7)
FLIP = {"ay", "az", "wy", "wz"}
TICK_S = (1e-3, 39.0625e-6, 1e-6)
GYRO_LSB = 2.0**-12
ACC_LSB = 2.0**-10


def _samples(f: Frames) -> pd.DataFrame:
    """(order, tag, type, value) of every ESF sample; ``order`` = file position."""
    parts = []
    raw = f.of((0x10, 0x03))
    if len(raw):
        n = (f.length[raw] - 4) // 8
        owner = np.repeat(raw, n)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n)
        pos = f.start[owner] + 6 + 4 + 8 * k
        words = np.ascontiguousarray(f.data[pos[:, None] + np.arange(8)[None, :]]).view("<u4").reshape(-1, 2)
        parts.append(pd.DataFrame({"order": f.start[owner] + k, "word": words[:, 0], "tag": words[:, 1]}))
    meas = f.of((0x10, 0x02))
    if len(meas):
        base = f.start[meas] + 6
        hdr = np.ascontiguousarray(f.data[base[:, None] + np.arange(8)[None, :]])
        tag = hdr[:, :4].copy().view("<u4").ravel()
        flags = hdr[:, 4:6].copy().view("<u2").ravel().astype(np.int64)
        n = (flags >> 11) & 0x1F
        owner = np.repeat(np.arange(len(meas)), n)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n)
        pos = base[owner] + 8 + 4 * k
        mwords = np.ascontiguousarray(f.data[pos[:, None] + np.arange(4)[None, :]]).view("<u4").ravel()
        parts.append(pd.DataFrame({"order": f.start[meas][owner] + k, "word": mwords, "tag": tag[owner]}))
    if not parts:
        return pd.DataFrame(columns=["order", "word", "tag", "type", "value"])
    s = pd.concat(parts, ignore_index=True).sort_values("order", kind="stable").reset_index(drop=True)
    w = s["word"].to_numpy(dtype=np.int64)
    s["type"] = (w >> 24) & 0x3F
    v = w & 0xFFFFFF
    s["value"] = np.where(v >= 1 << 23, v - (1 << 24), v)
    s["count"] = w & 0x7FFFFF
    tags = s["tag"].to_numpy(dtype=np.float64)
    jumps = np.concatenate(([0.0], np.cumsum(np.where(np.diff(tags) < -(2.0**31), 2.0**32, 0.0))))
    s["tag"] = tags + jumps
    return s


def _pairs(s: pd.DataFrame, epochs: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(sensor tag, GPS time) pairs: each GNSS epoch frame with the last ESF sample before it."""
    at, gt = epochs
    order = s["order"].to_numpy()
    j = np.searchsorted(order, at) - 1
    ok = j >= 0
    return s["tag"].to_numpy()[j[ok]], gt[ok]


def _imu(s: pd.DataFrame) -> pd.DataFrame | None:
    names = {**GYRO, **ACC}
    sel = s[s["type"].isin(list(names))]
    if not len(sel):
        return None
    scale = np.where(sel["type"].isin(list(GYRO)).to_numpy(), np.radians(GYRO_LSB), ACC_LSB)
    vals = pd.DataFrame(
        {"tag": sel["tag"].to_numpy(), "col": sel["type"].map(names).to_numpy(), "v": sel["value"].to_numpy() * scale}
    )
    imu = vals.pivot_table(index="tag", columns="col", values="v", aggfunc="last").reset_index()
    for c in ("ax", "ay", "az", "wx", "wy", "wz"):
        if c not in imu.columns:
            imu[c] = np.nan
        elif c in FLIP:
            imu[c] = -imu[c]
    return imu[["tag", "ax", "ay", "az", "wx", "wy", "wz"]]


def _tacho(s: pd.DataFrame) -> tuple[pd.DataFrame | None, int | None]:
    for typ in TICK_TYPES:
        sel = s[s["type"] == typ]
        if len(sel):
            c = sel["count"].to_numpy(dtype=np.int64)
            d = np.diff(c) % (1 << 23)
            pulses = np.concatenate(([c[0]], c[0] + np.cumsum(d)))
            return pd.DataFrame({"tag": sel["tag"].to_numpy(), "pulses": pulses}), typ
    return None, None


def read_esf(path: Path, f: Frames, dec: Decoded, epochs: tuple[np.ndarray, np.ndarray] | None) -> None:
    s = _samples(f)
    if not len(s):
        return
    if epochs is None:
        raise InputError(
            "ESF sensor data but no NAV-PVT or RXM-RAWX: the sensor clock cannot be put on GNSS time", path=path
        )
    tag, g = _pairs(s, epochs)
    if len(tag) < 2:
        raise InputError("fewer than 2 GNSS epochs after ESF samples: the sensor clock cannot be fitted", path=path)
    rough = float(np.ptp(g) / max(np.ptp(tag), 1e-12))
    unit = min(TICK_S, key=lambda u: abs(np.log(rough / u)))
    try:
        fit = fit_clock(tag * unit, g)
    except ValueError as exc:
        raise InputError(f"ESF sensor clock: {exc}", path=path) from exc
    dec.clock = {"stream": "imu/tacho (ESF)", "tick_s": unit, **fit.to_dict()}
    imu = _imu(s)
    if imu is not None:
        imu.insert(0, "gnss_time_s", fit.apply(imu.pop("tag").to_numpy() * unit))
        dec.frames["imu"] = imu
    tacho, typ = _tacho(s)
    if tacho is not None:
        tacho.insert(0, "gnss_time_s", fit.apply(tacho.pop("tag").to_numpy() * unit))
        dec.frames["tacho"] = tacho
        dec.notes.append(f"tacho from ESF data type {typ}")
    other = ~s["type"].isin([*GYRO, *ACC, typ])
    for t, n in s.loc[other, "type"].value_counts().items():
        dec.skipped[f"ESF samples of data type {t} not imported"] += int(n)


# ---------------------------------------------------------------------------------------
# writer


def _word(typ: int, value: np.ndarray) -> np.ndarray:
    return ((typ & 0x3F) << 24) | (value.astype(np.int64) & 0xFFFFFF)


def esf_frames(
    imu: pd.DataFrame | None, tacho: pd.DataFrame | None, *, t_ref_gps: float, drift: float = 0.0
) -> list[tuple[float, bytes]]:
    """(GPS time, frame): ESF-RAW per imu row, ESF-MEAS (single tick) per tacho row.

    Sensor time tags in ms of a clock that started at ``t_ref_gps`` and runs ``1 + drift``
    times GNSS time (a drifting recorder for the tests)."""
    from fieldlogs.recorders.ubx_frames import frame

    out: list[tuple[float, bytes]] = []
    if imu is not None and len(imu):
        g = imu["gnss_time_s"].to_numpy(dtype=float)
        tag = np.round((g - t_ref_gps) * (1.0 + drift) * 1000.0).astype(np.int64)
        words = []
        for typ, col in {**GYRO, **ACC}.items():
            v = imu[col].to_numpy(dtype=float) * (-1.0 if col in FLIP else 1.0)
            lsb = np.radians(GYRO_LSB) if typ in GYRO else ACC_LSB
            words.append(_word(typ, np.round(v / lsb)))
        w = np.stack(words, axis=1)
        for i in range(len(g)):
            body = (
                np.zeros(4, np.uint8).tobytes()
                + np.column_stack((w[i], np.full(len(w[i]), tag[i]))).astype("<u4").tobytes()
            )
            out.append((float(g[i]), frame(0x10, 0x03, body)))
    if tacho is not None and len(tacho):
        g = tacho["gnss_time_s"].to_numpy(dtype=float)
        tag = np.round((g - t_ref_gps) * (1.0 + drift) * 1000.0).astype(np.int64)
        p = tacho["pulses"].to_numpy(dtype=np.int64) % (1 << 23)
        for i in range(len(g)):
            body = (
                np.array([tag[i]], "<u4").tobytes()
                + np.array([1 << 11], "<u2").tobytes()
                + np.zeros(2, np.uint8).tobytes()
                + np.array([_word(10, p[i : i + 1])[0]], "<u4").tobytes()
            )
            out.append((float(g[i]), frame(0x10, 0x02, body)))
    return out
