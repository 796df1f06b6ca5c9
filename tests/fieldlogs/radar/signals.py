"""Hand-made IF samples (written out here, not with the simulator): point reflectors at a
constant range and Doppler, f_k's echo A·exp(j(2π·f_d·t − 4π·f_k·R/c)), f1 sampled at
t_n = n·2·T_pri and f2 at t_n + T_pri, plus white complex noise and a static echo."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from schemas.radar import RadarParams

C = 299_792_458.0
TABLE1 = RadarParams(24.06e9, 12.75e6, 50e-6, 0.307, 0.8, 45.0, 7.5, 3.0)


def reflectors_if(
    p: RadarParams,
    fd_hz: Sequence[float],
    range_m: Sequence[float],
    *,
    frames: int = 2,
    amp: float | Sequence[float] = 0.1,
    noise: float = 1e-4,
    static: complex = 0.0,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    n = frames * p.samples_per_frame
    t = np.arange(n) * 2 * p.t_pri_s
    amps = np.broadcast_to(np.asarray(amp, dtype=float), (len(fd_hz),))
    out: dict[str, np.ndarray] = {"t": t}
    for k, (f, dt) in enumerate(((p.f0_hz, 0.0), (p.f0_hz + p.delta_f_hz, p.t_pri_s)), start=1):
        z = np.full(n, static, dtype=np.complex128)
        for a, fd, r in zip(amps, fd_hz, range_m, strict=True):
            z += a * np.exp(1j * (2 * np.pi * fd * (t + dt) - 4 * np.pi * f * r / C))
        z += noise * (rng.standard_normal(n) + 1j * rng.standard_normal(n)) / np.sqrt(2)
        out[f"i{k}"], out[f"q{k}"] = z.real.astype(np.float32), z.imag.astype(np.float32)
    return out


def reflector_if(p: RadarParams, fd_hz: float, range_m: float, **kw: object) -> dict[str, np.ndarray]:
    return reflectors_if(p, [fd_hz], [range_m], **kw)  # type: ignore[arg-type]


def ground_if(p: RadarParams, v_g: float, degrees: Sequence[float], **kw: object) -> dict[str, np.ndarray]:
    """Reflectors on flat ground seen at depressions θ_m, the vehicle moving at v_g (+: toward
    where the radar looks): f_d = 2·v_g·cos θ_m/λ, R = h/sin θ_m (eq. 1 holds exactly)."""
    th = np.radians(np.asarray(degrees, dtype=float))
    fd = 2 * v_g * np.cos(th) / p.wavelength_m
    return reflectors_if(p, list(fd), list(p.height_m / np.sin(th)), **kw)  # type: ignore[arg-type]
