"""A realistic GPS / Galileo / QZSS constellation generated *as broadcast ephemerides*.

Each satellite has mean elements at a reference epoch t_ref — √A, e, i, ω, the ECEF longitude
of its ascending node λ_ref and mean anomaly M_ref — plus constant harmonic coefficients,
Δn, Ω̇, IDOT and a clock (af0, af1, TGD or BGDs). Broadcast records at each Toe T follow the
ICD's own linear model (IS-GPS-200N Table 20-IV), so consecutive records describe the same
orbit and the truth can be evaluated from the same records as the solver's:

* M0 = M_ref + (√(μ/A³) + Δn)(T − t_ref); i0 = i_ref + IDOT·(T − t_ref);
* Ω0 = λ_ref + (Ω̇ − Ω̇e)(T − t_ref) + Ω̇e·Toe (so that Ω_k(T) = Ω0 − Ω̇e·Toe, the node's
  ECEF longitude, moves at Ω̇ − Ω̇e), wrapped to (−π, π];
* af0 = af0_ref + af1·(T − t_ref), toc = Toe.

Layouts (nominal values as published by the operators):

* GPS: 31 satellites in 6 planes (A–F, 60° apart) on the 24 baseline slots of the GPS SPS
  Performance Standard (Table 3-1) plus 7 in the planes' largest gaps, i ≈ 55°,
  A ≈ 26 560 km (√A ≈ 5153.7), e 0.002–0.02; Toe every 2 h, fit 4 h, URA 2.4 m (SVacc);
* Galileo: Walker 24/3/1, i ≈ 56°, A ≈ 29 600 km (√A ≈ 5440.6), e < 0.001; I/NAV records
  (DataSrc 517) and F/NAV records (DataSrc 258) every 10 min, SISA 3.12 m;
* QZSS: three quasi-zenith IGSO (A = 42 164 km, e ≈ 0.075, i ≈ 41°, ω = 270°, ground track
  centred on 135° E, 8 h apart) and one GEO at 127° E; Toe every 15 min, 2 h fit (flag 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import NAV_COLUMNS, SYSTEMS, WEEK_S, FloatArray
from fieldlogs.gnss.ephemeris import nav_table, satellite_states

_TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class MeanOrbit:
    """Mean elements and clock of one satellite at ``t_ref`` (module docstring)."""

    sat: str
    sqrt_a: float
    ecc: float
    inc: float
    omega: float
    node_lon: float
    mean_anomaly: float
    delta_n: float
    omega_dot: float
    idot: float
    harmonics: tuple[float, float, float, float, float, float]
    """(Cuc, Cus, Crc, Crs, Cic, Cis)."""
    af0: float
    af1: float
    group_delay: tuple[float, float]
    """GPS/QZSS (TGD, 0); Galileo (BGD E1/E5a, BGD E1/E5b) [s]."""


def _harmonics(rng: np.random.Generator, scale: float = 1.0) -> tuple[float, float, float, float, float, float]:
    cuc, cus = rng.normal(0.0, 4e-6 * scale), rng.normal(0.0, 8e-6 * scale)
    crc, crs = rng.uniform(150.0, 350.0) * scale, rng.normal(0.0, 80.0) * scale
    cic, cis = rng.normal(0.0, 1e-7 * scale), rng.normal(0.0, 1e-7 * scale)
    return (cuc, cus, crc, crs, cic, cis)


def _clock(rng: np.random.Generator) -> tuple[float, float]:
    return rng.uniform(-6e-4, 6e-4), rng.normal(0.0, 4e-12)


# GPS SPS Performance Standard (2001) Table 3-1 "Reference Orbit Slot Assignments as of the
# Defined Epoch": plane RAAN [deg] and the slots' arguments of latitude [deg] (A1..A4, B1..B4, ...).
GPS_SLOTS: dict[str, tuple[float, tuple[float, float, float, float]]] = {
    "A": (272.847, (268.126, 161.786, 11.676, 41.806)),
    "B": (332.847, (80.956, 173.336, 309.976, 204.376)),
    "C": (32.847, (111.876, 11.796, 339.666, 241.556)),
    "D": (92.847, (135.226, 265.446, 35.156, 167.356)),
    "E": (152.847, (197.046, 302.596, 66.066, 333.686)),
    "F": (212.847, (238.886, 345.226, 105.206, 135.346)),
}


def _gps_layout() -> list[tuple[float, float]]:
    """(RAAN, argument of latitude) [deg] of 31 satellites: the 24 baseline slots, then one more
    per plane in its largest gap and a second in plane B (the operational constellation's
    extra satellites sit in such expanded/fore-aft positions)."""
    out: list[tuple[float, float]] = []
    for raan, slots in GPS_SLOTS.values():
        out.extend((raan, u) for u in slots)
    for plane in ("A", "B", "C", "D", "E", "F", "B"):
        raan = GPS_SLOTS[plane][0]
        us = np.sort([u for r, u in out if r == raan])
        gaps = np.diff(np.concatenate([us, [us[0] + 360.0]]))
        k = int(np.argmax(gaps))
        out.append((raan, float((us[k] + gaps[k] / 2.0) % 360.0)))
    return out


def gps_orbits(rng: np.random.Generator) -> list[MeanOrbit]:
    """31 GPS satellites on the published slot layout (``_gps_layout``); the whole constellation
    is rotated by a seeded angle against the Earth, and e, ω, i are drawn within the SPS PS
    tolerances (e 0–0.02, i 55° ± 1°)."""
    out = []
    lon0 = rng.uniform(0.0, _TWO_PI)
    for prn, (raan, u) in enumerate(_gps_layout(), start=1):
        af0, af1 = _clock(rng)
        omega = rng.uniform(-np.pi, np.pi)
        out.append(
            MeanOrbit(
                sat=f"G{prn:02d}",
                sqrt_a=5153.7 + rng.normal(0.0, 0.3),
                ecc=rng.uniform(0.002, 0.02),
                inc=np.radians(55.0 + rng.normal(0.0, 1.0)),
                omega=omega,
                node_lon=lon0 + np.radians(raan),
                mean_anomaly=np.radians(u) - omega,
                delta_n=4.5e-9 + rng.normal(0.0, 5e-10),
                omega_dot=-8.0e-9 + rng.normal(0.0, 3e-10),
                idot=rng.normal(0.0, 3e-10),
                harmonics=_harmonics(rng),
                af0=af0,
                af1=af1,
                group_delay=(rng.normal(0.0, 5e-9), 0.0),
            )
        )
    return out


def galileo_orbits(rng: np.random.Generator) -> list[MeanOrbit]:
    """Walker 24/3/1 Galileo constellation."""
    out = []
    lon0 = rng.uniform(0.0, _TWO_PI)
    for k in range(3):
        for j in range(8):
            af0, af1 = _clock(rng)
            out.append(
                MeanOrbit(
                    sat=f"E{k * 8 + j + 1:02d}",
                    sqrt_a=5440.6 + rng.normal(0.0, 0.05),
                    ecc=rng.uniform(1e-4, 6e-4),
                    inc=np.radians(56.0 + rng.normal(0.0, 0.3)),
                    omega=rng.uniform(-np.pi, np.pi),
                    node_lon=lon0 + np.radians(120.0 * k),
                    mean_anomaly=_TWO_PI * j / 8 + np.radians(15.0 * k),
                    delta_n=3.2e-9 + rng.normal(0.0, 2e-10),
                    omega_dot=-5.6e-9 + rng.normal(0.0, 2e-10),
                    idot=rng.normal(0.0, 2e-10),
                    harmonics=_harmonics(rng, 0.6),
                    af0=af0,
                    af1=af1,
                    group_delay=(rng.normal(0.0, 3e-9), rng.normal(0.0, 3e-9)),
                )
            )
    return out


def _centre_longitude(orbit: MeanOrbit, t_ref: float) -> float:
    """Circular mean ECEF longitude of an orbit over one sidereal day."""
    nav = records([orbit], t_ref, t_ref + 1.0, 3600.0, t_ref)
    table = nav_table(nav)
    t = t_ref + np.linspace(0.0, 86_164.0, 97)
    st = satellite_states(table, np.zeros(t.size, dtype=np.int64), t)
    lon = np.arctan2(st.pos[:, 1], st.pos[:, 0])
    return float(np.arctan2(np.mean(np.sin(lon)), np.mean(np.cos(lon))))


def qzss_orbits(rng: np.random.Generator, t_ref: float) -> list[MeanOrbit]:
    """Three quasi-zenith IGSO (centred on 135° E) and one GEO (127° E)."""
    sqrt_a = float(np.sqrt(42_164_140.0))
    out = []
    for name, k in (("J01", 0), ("J02", 1), ("J04", 2)):
        af0, af1 = _clock(rng)
        out.append(
            MeanOrbit(
                sat=name,
                sqrt_a=sqrt_a + rng.normal(0.0, 0.05),
                ecc=0.075 + rng.normal(0.0, 0.002),
                inc=np.radians(41.0 + rng.normal(0.0, 0.5)),
                omega=np.radians(270.0),
                node_lon=np.radians(-120.0 * k),
                mean_anomaly=np.radians(-120.0 * k),
                delta_n=rng.normal(0.0, 1e-10),
                omega_dot=-1.5e-9,
                idot=0.0,
                harmonics=_harmonics(rng, 0.4),
                af0=af0,
                af1=af1,
                group_delay=(rng.normal(0.0, 5e-9), 0.0),
            )
        )
    af0, af1 = _clock(rng)
    out.append(
        MeanOrbit(
            "J03", sqrt_a, 2e-4, np.radians(0.06), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, (0.0,) * 6, af0, af1, (2e-9, 0.0)
        )
    )
    shifted = []
    for orb, centre in zip(out, (135.0, 135.0, 135.0, 127.0), strict=True):
        d = np.radians(centre) - _centre_longitude(orb, t_ref)
        shifted.append(_replace_lon(orb, orb.node_lon + d))
    return shifted


def _replace_lon(orb: MeanOrbit, lon: float) -> MeanOrbit:
    from dataclasses import replace

    return replace(orb, node_lon=lon)


def _wrap(a: FloatArray) -> FloatArray:
    return np.mod(a + np.pi, _TWO_PI) - np.pi


def records(orbits: list[MeanOrbit], t0: float, t1: float, spacing_s: float, t_ref: float) -> pd.DataFrame:
    """Broadcast records of ``orbits`` for Toe on the ``spacing_s`` grid covering [t0, t1]."""
    toes = np.arange(np.floor(t0 / spacing_s) * spacing_s, t1 + spacing_s, spacing_s)
    rows: list[dict[str, float | str]] = []
    for orb in orbits:
        sys = orb.sat[0]
        mu = SYSTEMS[sys].mu_m3ps2
        we = SYSTEMS[sys].omega_e_radps
        n = np.sqrt(mu / orb.sqrt_a**6) + orb.delta_n
        dt = toes - t_ref
        week = np.floor(toes / WEEK_S)
        toe_w = toes - week * WEEK_S
        m0 = _wrap(orb.mean_anomaly + n * dt)
        om0 = _wrap(orb.node_lon + (orb.omega_dot - we) * dt + we * toe_w)
        cuc, cus, crc, crs, cic, cis = orb.harmonics
        for i, toe in enumerate(toes):
            base: dict[str, float | str] = {
                "sat": orb.sat,
                "toc_gps_s": float(toe),
                "SVclockBias": orb.af0 + orb.af1 * float(dt[i]),
                "SVclockDrift": orb.af1,
                "SVclockDriftRate": 0.0,
                "IODE": float((int(toe // spacing_s)) % 256),
                "Crs": crs,
                "DeltaN": orb.delta_n,
                "M0": float(m0[i]),
                "Cuc": cuc,
                "Eccentricity": orb.ecc,
                "Cus": cus,
                "sqrtA": orb.sqrt_a,
                "Toe": float(toe_w[i]),
                "Cic": cic,
                "Omega0": float(om0[i]),
                "Cis": cis,
                "Io": orb.inc + orb.idot * float(dt[i]),
                "Crc": crc,
                "omega": orb.omega,
                "OmegaDot": orb.omega_dot,
                "IDOT": orb.idot,
                "health": 0.0,
                "TransTime": float(toe_w[i] - min(spacing_s, 1800.0)),
                "week": float(week[i]),
            }
            rows.extend(_system_fields(base, orb, sys))
    return pd.DataFrame(rows, columns=list(NAV_COLUMNS))


def _system_fields(base: dict[str, float | str], orb: MeanOrbit, sys: str) -> list[dict[str, float | str]]:
    nan = float("nan")
    if sys == "E":
        common = {
            "TGD": nan,
            "SVacc": 3.12,
            "FitIntvl": nan,
            "BGDe5a": orb.group_delay[0],
            "BGDe5b": orb.group_delay[1],
        }
        return [{**base, **common, "DataSrc": 517.0}, {**base, **common, "DataSrc": 258.0}]
    fit = 4.0 if sys == "G" else 0.0
    extra = {"TGD": orb.group_delay[0], "SVacc": 2.4, "FitIntvl": fit, "BGDe5a": nan, "BGDe5b": nan, "DataSrc": nan}
    return [{**base, **extra}]


TOE_SPACING_S = {"G": 7200.0, "E": 600.0, "J": 900.0}


def constellation_nav(
    t0: float, t1: float, seed: int, systems: tuple[str, ...] = ("G", "E", "J"), t_ref: float | None = None
) -> pd.DataFrame:
    """``gnss_nav`` rows of the whole constellation for GPS times [t0, t1] (module docstring)."""
    rng = np.random.default_rng(seed)
    ref = t0 if t_ref is None else t_ref
    frames = []
    gps, gal, qzs = gps_orbits(rng), galileo_orbits(rng), qzss_orbits(rng, ref)
    for sys, orbits in (("G", gps), ("E", gal), ("J", qzs)):
        if sys in systems:
            frames.append(records(orbits, t0 - 7200.0, t1 + 7200.0, TOE_SPACING_S[sys], ref))
    return pd.concat(frames, ignore_index=True)
