"""Decoding of SBAS L1 messages (RTCA DO-229 Appendix A), vectorised over the messages of a type.

Bit layouts (the field tables are in :mod:`fieldlogs.simulate.gnss.sbas_encode`'s docstring, each with
its DO-229 table): positions count from bit 0, the first preamble bit, so the data of every
type start at bit 14. Each decoder takes the (N, 256) bits of N messages of its type and their
reception times ``t_rx`` [GPS s] and SBAS PRNs ``geo``, and returns one row per message and
slot (mask slot, IGP position) in SI units:

* MT 1 → ``masks`` (t_rx, geo, iodp, slot 1…, prn): the PRN-mask bits set, in order;
* MT 2–5 and the first part of MT 24 → ``fast`` (t_rx, geo, mt, iodf, iodp, slot, prc_m,
  udrei); MT 2 holds slots 1–13, MT 3 14–26, MT 4 27–39, MT 5 40–51, MT 24 with block ID b
  the slots 13b + 1 … 13b + 6;
* MT 6 → ``integrity`` (t_rx, geo, slot, udrei, iodf): IODF_j of the fast-correction type
  whose slots it updates (IODF 3: alert, matches any);
* MT 7 → ``degradation`` (t_rx, geo, iodp, t_lat_s, slot, ai);
* MT 10 → ``mt10`` (t_rx, geo and the parameters of ``encode.Mt10``);
* MT 25 and the second half of MT 24 → ``long_term`` (t_rx, geo, iodp, slot, iode, velocity,
  dx_m, dy_m, dz_m, daf0_s, ddx_mps, ddy_mps, ddz_mps, daf1_sps, t0_sod_s);
* MT 18 → ``igp_mask`` (t_rx, geo, iodi, band, n_bands, igp 1…201, order 0…: position among
  the band's set bits);
* MT 26 → ``iono`` (t_rx, geo, iodi, band, order = 15·block + position, delay_code, givei);
* MT 0 → ``mt0`` (t_rx, geo): "do not use this SBAS";
* MT 9 → ``geo_nav``, MT 12 → ``network_time``, MT 17 → ``almanacs``, MT 27 → ``service``
  (δUDRE regions), MT 28 → ``covariance`` (each decoder's docstring; the layouts are
  ``encode``'s).

Not decoded (counted as such by the stream reader): MT 62/63 (internal test, null) and the
types DO-229 leaves spare.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fieldlogs.gnss.sbas.bits import Bits, IntArray, getbits, getbitu

FloatArray = np.ndarray


def fields_u(bits: Bits, start: int, width: int, count: int) -> IntArray:
    """``count`` consecutive unsigned fields of ``width`` bits from ``start``: (N, count)."""
    seg = bits[:, start : start + width * count].astype(np.int64).reshape(bits.shape[0], count, width)
    w = (1 << np.arange(width - 1, -1, -1, dtype=np.int64)).astype(np.int64)
    return np.asarray(seg @ w, dtype=np.int64)


def fields_s(bits: Bits, start: int, width: int, count: int) -> IntArray:
    u = fields_u(bits, start, width, count)
    return np.where(u >= (1 << (width - 1)), u - (1 << width), u)


def _long(base: dict[str, np.ndarray], per_slot: dict[str, np.ndarray], keep: np.ndarray | None = None) -> pd.DataFrame:
    """One row per (message, slot): ``base`` (N,) repeated, ``per_slot`` (N, K) flattened."""
    k = next(iter(per_slot.values())).shape[1]
    cols = {c: np.repeat(v, k) for c, v in base.items()}
    cols.update({c: v.reshape(-1) for c, v in per_slot.items()})
    df = pd.DataFrame(cols)
    return df if keep is None else df.loc[keep.reshape(-1)].reset_index(drop=True)


def decode_mt1(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    mask = bits[:, 14:224].astype(bool)
    iodp = getbitu(bits, 224, 2)
    slot = np.cumsum(mask, axis=1)
    prn = np.broadcast_to(np.arange(1, 211), mask.shape)
    df = _long({"t_rx": t_rx, "geo": geo, "iodp": iodp}, {"slot": slot, "prn": prn}, keep=mask)
    return df


def decode_fast(bits: Bits, t_rx: FloatArray, geo: IntArray, mt: IntArray) -> pd.DataFrame:
    """MT 2–5 (Table A-4)."""
    iodf, iodp = getbitu(bits, 14, 2), getbitu(bits, 16, 2)
    prc = fields_s(bits, 18, 12, 13) * 0.125
    udrei = fields_u(bits, 174, 4, 13)
    slot = (mt - 2)[:, None] * 13 + np.arange(1, 14)[None, :]
    return _long(
        {"t_rx": t_rx, "geo": geo, "mt": mt, "iodf": iodf, "iodp": iodp}, {"slot": slot, "prc_m": prc, "udrei": udrei}
    )


def decode_mt6(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    """MT 6 (Table A-5): IODF of the block each slot belongs to."""
    iodfs = fields_u(bits, 14, 2, 4)
    udrei = fields_u(bits, 22, 4, 51)
    slot = np.broadcast_to(np.arange(1, 52), udrei.shape)
    iodf = iodfs[:, np.minimum((np.arange(51)) // 13, 3)]
    return _long({"t_rx": t_rx, "geo": geo}, {"slot": slot, "udrei": udrei, "iodf": iodf})


def decode_mt7(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    """MT 7 (Table A-7)."""
    ai = fields_u(bits, 22, 4, 51)
    slot = np.broadcast_to(np.arange(1, 52), ai.shape)
    base = {"t_rx": t_rx, "geo": geo, "t_lat_s": getbitu(bits, 14, 4).astype(float), "iodp": getbitu(bits, 18, 2)}
    return _long(base, {"slot": slot, "ai": ai})


#: MT 10 fields: (name, bits, LSB) in order (Table A-9).
MT10_FIELDS = (
    ("b_rrc", 10, 0.002), ("c_ltc_lsb", 10, 0.002), ("c_ltc_v1", 10, 0.00005), ("i_ltc_v1", 9, 1.0),
    ("c_ltc_v0", 10, 0.002), ("i_ltc_v0", 9, 1.0), ("c_geo_lsb", 10, 0.0005), ("c_geo_v", 10, 0.00005),
    ("i_geo", 9, 1.0), ("c_er", 6, 0.5), ("c_iono_step", 10, 0.001), ("i_iono", 9, 1.0),
    ("c_iono_ramp", 10, 0.000005), ("rss_udre", 1, 1.0), ("rss_iono", 1, 1.0), ("c_covariance", 7, 0.1),
)  # fmt: skip


def decode_mt10(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    cols: dict[str, np.ndarray] = {"t_rx": t_rx, "geo": geo}
    pos = 14
    for name, n, lsb in MT10_FIELDS:
        cols[name] = getbitu(bits, pos, n) * lsb
        pos += n
    return pd.DataFrame(cols)


def _ltc_half(bits: Bits, start: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The 106-bit long-term half at ``start`` (Tables A-10, A-11): (N, 2) per-satellite fields
    (the second column empty for velocity code 1) and the IODP."""
    vel = getbitu(bits, start, 1) == 1
    n = bits.shape[0]
    out: dict[str, np.ndarray] = {
        c: np.zeros((n, 2)) for c in ("dx_m", "dy_m", "dz_m", "daf0_s", "ddx_mps", "ddy_mps", "ddz_mps", "daf1_sps")
    }
    out["t0_sod_s"] = np.full((n, 2), np.nan)
    slot, iode = np.zeros((n, 2), dtype=np.int64), np.zeros((n, 2), dtype=np.int64)
    # velocity code 0: two satellites of 51 bits each, IODP at +103
    for k in range(2):
        p = start + 1 + 51 * k
        slot[:, k], iode[:, k] = getbitu(bits, p, 6), getbitu(bits, p + 6, 8)
        for j, c in enumerate(("dx_m", "dy_m", "dz_m")):
            out[c][:, k] = getbits(bits, p + 14 + 9 * j, 9) * 0.125
        out["daf0_s"][:, k] = getbits(bits, p + 41, 10) * 2.0**-31
    iodp = getbitu(bits, start + 103, 2)
    # velocity code 1: one satellite
    p = start + 1
    v = {c: getbits(bits, p + 14 + 11 * j, 11) * 0.125 for j, c in enumerate(("dx_m", "dy_m", "dz_m"))}
    v["daf0_s"] = getbits(bits, p + 47, 11) * 2.0**-31
    for j, c in enumerate(("ddx_mps", "ddy_mps", "ddz_mps")):
        v[c] = getbits(bits, p + 58 + 8 * j, 8) * 2.0**-11
    v["daf1_sps"] = getbits(bits, p + 82, 8) * 2.0**-39
    v["t0_sod_s"] = getbitu(bits, p + 90, 13) * 16.0
    for c, val in v.items():
        out[c][:, 0] = np.where(vel, val, out[c][:, 0])
        out[c][:, 1] = np.where(vel, 0.0 if c != "t0_sod_s" else np.nan, out[c][:, 1])
    slot[:, 0] = np.where(vel, getbitu(bits, p, 6), slot[:, 0])
    iode[:, 0] = np.where(vel, getbitu(bits, p + 6, 8), iode[:, 0])
    slot[:, 1] = np.where(vel, 0, slot[:, 1])
    iodp = np.where(vel, getbitu(bits, p + 103, 2), iodp)
    out["slot"], out["iode"] = slot, iode
    out["velocity"] = np.repeat(vel[:, None], 2, axis=1)
    return out, iodp


def decode_long_term(bits: Bits, t_rx: FloatArray, geo: IntArray, starts: tuple[int, ...]) -> pd.DataFrame:
    """Long-term halves at bit ``starts`` (MT 25: 14 and 120; MT 24: 120)."""
    frames = []
    for s in starts:
        per, iodp = _ltc_half(bits, s)
        keep = per["slot"] > 0
        frames.append(_long({"t_rx": t_rx, "geo": geo, "iodp": iodp}, per, keep=keep))
    return pd.concat(frames, ignore_index=True)


def decode_mt24_fast(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    prc = fields_s(bits, 14, 12, 6) * 0.125
    udrei = fields_u(bits, 86, 4, 6)
    iodp, block, iodf = getbitu(bits, 110, 2), getbitu(bits, 112, 2), getbitu(bits, 114, 2)
    slot = block[:, None] * 13 + np.arange(1, 7)[None, :]
    base = {"t_rx": t_rx, "geo": geo, "mt": np.full(t_rx.size, 24), "iodf": iodf, "iodp": iodp}
    return _long(base, {"slot": slot, "prc_m": prc, "udrei": udrei})


def decode_mt18(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    mask = bits[:, 24:225].astype(bool)
    order = np.cumsum(mask, axis=1) - 1
    igp = np.broadcast_to(np.arange(1, 202), mask.shape)
    base = {
        "t_rx": t_rx, "geo": geo, "n_bands": getbitu(bits, 14, 4), "band": getbitu(bits, 18, 4),
        "iodi": getbitu(bits, 22, 2),
    }  # fmt: skip
    return _long(base, {"igp": igp, "order": order}, keep=mask)


def decode_mt26(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    band, block = getbitu(bits, 14, 4), getbitu(bits, 18, 4)
    cells = fields_u(bits, 22, 13, 15)
    delay, givei = cells >> 4, cells & 0xF
    order = block[:, None] * 15 + np.arange(15)[None, :]
    base = {"t_rx": t_rx, "geo": geo, "band": band, "iodi": getbitu(bits, 217, 2)}
    return _long(base, {"order": order, "delay_code": delay, "givei": givei})


#: MT 9 fields after the 8 reserved bits: (name, bits, LSB, signed).
MT9_FIELDS = (
    ("t0_sod_s", 13, 16.0, False), ("ura", 4, 1.0, False), ("x_m", 30, 0.08, True), ("y_m", 30, 0.08, True),
    ("z_m", 25, 0.4, True), ("vx_mps", 17, 0.000625, True), ("vy_mps", 17, 0.000625, True),
    ("vz_mps", 18, 0.004, True), ("ax_mps2", 10, 0.0000125, True), ("ay_mps2", 10, 0.0000125, True),
    ("az_mps2", 10, 0.0000625, True), ("af0_s", 12, 2.0**-31, True), ("af1_sps", 8, 2.0**-40, True),
)  # fmt: skip
#: MT 12 fields: (name, bits, LSB, signed).
MT12_FIELDS = (
    ("a1_sps", 24, 2.0**-50, True), ("a0_s", 32, 2.0**-30, True), ("t0t_s", 8, 4096.0, False),
    ("wn_t", 8, 1.0, False), ("dt_ls", 8, 1.0, True), ("wn_lsf", 8, 1.0, False), ("dn", 8, 1.0, False),
    ("dt_lsf", 8, 1.0, True), ("utc_id", 3, 1.0, False), ("gps_tow_s", 20, 1.0, False),
    ("gps_week", 10, 1.0, False), ("glonass", 1, 1.0, False), ("glonass_da_s", 24, 2.0**-31, True),
)  # fmt: skip


def _fields(bits: Bits, start: int, spec: tuple[tuple[str, int, float, bool], ...]) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    pos = start
    for name, n, lsb, signed in spec:
        out[name] = (getbits if signed else getbitu)(bits, pos, n) * lsb
        pos += n
    return out


def decode_mt9(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    """MT 9 → ``geo_nav`` (t_rx, geo and the fields of ``encode.GeoNav``)."""
    return pd.DataFrame({"t_rx": t_rx, "geo": geo, **_fields(bits, 22, MT9_FIELDS)})


def decode_mt12(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    """MT 12 → ``network_time`` (t_rx, geo and the fields of ``encode.NetworkTime``)."""
    return pd.DataFrame({"t_rx": t_rx, "geo": geo, **_fields(bits, 14, MT12_FIELDS)})


def decode_mt17(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    """MT 17 → ``almanacs``: one row per almanac with a PRN (t_rx, geo, t0_sod_s, data_id, prn,
    health, x_m … vz_mps)."""
    names = ("data_id", "prn", "health", "x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps")
    per: dict[str, np.ndarray] = {c: np.zeros((bits.shape[0], 3)) for c in names}
    spec = (("data_id", 2, 1.0, False), ("prn", 8, 1.0, False), ("health", 8, 1.0, False), ("x_m", 15, 2600.0, True),
            ("y_m", 15, 2600.0, True), ("z_m", 9, 26000.0, True), ("vx_mps", 3, 10.0, True), ("vy_mps", 3, 10.0, True),
            ("vz_mps", 4, 60.0, True))  # fmt: skip
    for k in range(3):
        for c, v in _fields(bits, 14 + 67 * k, spec).items():
            per[c][:, k] = v
    base = {"t_rx": t_rx, "geo": geo, "t0_sod_s": getbitu(bits, 215, 11) * 64.0}
    return _long(base, per, keep=per["prn"] > 0)


def decode_mt27(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    """MT 27 → ``service``: one row per message and region (t_rx, geo, iods, n_messages, number,
    n_regions, priority, inside, outside — the δUDRE indicators — region 0…, lat1, lon1, lat2,
    lon2 [deg], square); a message without a region gives one row with region −1."""
    head = {
        "t_rx": t_rx, "geo": geo, "iods": getbitu(bits, 14, 3), "n_messages": getbitu(bits, 17, 3) + 1,
        "number": getbitu(bits, 20, 3) + 1, "n_regions": getbitu(bits, 23, 3), "priority": getbitu(bits, 26, 2),
        "inside": getbitu(bits, 28, 4), "outside": getbitu(bits, 32, 4),
    }  # fmt: skip
    n = bits.shape[0]
    per: dict[str, np.ndarray] = {
        c: np.zeros((n, 5), dtype=np.int64) for c in ("lat1", "lon1", "lat2", "lon2", "square")
    }
    for k in range(5):
        p = 36 + 35 * k
        per["lat1"][:, k], per["lon1"][:, k] = getbits(bits, p, 8), getbits(bits, p + 8, 9)
        per["lat2"][:, k], per["lon2"][:, k] = getbits(bits, p + 17, 8), getbits(bits, p + 25, 9)
        per["square"][:, k] = getbitu(bits, p + 34, 1)
    region = np.broadcast_to(np.arange(5), (n, 5))
    keep = region < head["n_regions"][:, None]
    per["region"] = np.where(keep, region, -1)
    keep = keep | ((head["n_regions"] == 0)[:, None] & (region == 0))
    out = _long(head, per, keep=keep)
    return out.assign(square=out["square"].astype(bool))


def decode_mt28(bits: Bits, t_rx: FloatArray, geo: IntArray) -> pd.DataFrame:
    """MT 28 → ``covariance``: one row per satellite with a mask slot (t_rx, geo, iodp, slot,
    scale_exponent, e11 … e34 as integers)."""
    n = bits.shape[0]
    names = ("e11", "e22", "e33", "e44", "e12", "e13", "e14", "e23", "e24", "e34")
    per: dict[str, np.ndarray] = {c: np.zeros((n, 2), dtype=np.int64) for c in ("slot", "scale_exponent", *names)}
    for k in range(2):
        p = 16 + 105 * k
        per["slot"][:, k], per["scale_exponent"][:, k] = getbitu(bits, p, 6), getbitu(bits, p + 6, 3)
        for j, c in enumerate(names[:4]):
            per[c][:, k] = getbitu(bits, p + 9 + 9 * j, 9)
        for j, c in enumerate(names[4:]):
            per[c][:, k] = getbits(bits, p + 45 + 10 * j, 10)
    return _long({"t_rx": t_rx, "geo": geo, "iodp": getbitu(bits, 14, 2)}, per, keep=per["slot"] > 0)
