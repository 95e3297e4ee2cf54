"""How one road reaches both axles: :func:`delay_characteristic`, the rear wheel's delay
behind the front over a window's speed profile; and how far it reaches in frequency:
:func:`spatial_band`; and how alike the left and right tracks are: :func:`track_coherence`."""

from __future__ import annotations

import numpy as np
from scipy import special


def delay_characteristic(
    omega: np.ndarray, wheelbase_m: float, speed_mps: float | np.ndarray
) -> np.ndarray:
    """φ(ω) = E[exp(-iωτ)], τ = L/v, over the samples' speeds weighted by speed.

    The road velocity's intensity grows with speed (white in time at ``w = 2``), so a
    faster stretch weighs more. A constant speed gives the exact wheelbase delay.
    """
    v = np.atleast_1d(np.asarray(speed_mps, dtype=float))
    if np.ptp(v) <= 1e-9 * v.mean():  # as ever (the recorded sample bags replay bit for bit)
        return np.exp(-1j * omega * wheelbase_m / v.mean())
    tau, weights = _delays(wheelbase_m, v)
    return np.exp(-1j * np.multiply.outer(omega, tau)) @ weights


def delay_slope(omega: np.ndarray, wheelbase_m: float, speed_mps: float | np.ndarray) -> np.ndarray:
    """dφ/dL of :func:`delay_characteristic`: every delay ``τ = L/v`` scales with ``L`` (the
    weights stay), so ``dφ/dL = E[-iω τ/L exp(-iωτ)]``."""
    tau, weights = _delays(wheelbase_m, speed_mps)
    arg = -1j * np.multiply.outer(omega, tau)
    return (arg * np.exp(arg)) @ weights / wheelbase_m


def _delays(wheelbase_m: float, speed_mps: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the delays τ [s], their weights summing to 1): one for a constant speed, else the
    delays' distribution on 64 bins weighted by speed (cheap, and exact to far below the band:
    a faster stretch weighs more)."""
    v = np.atleast_1d(np.asarray(speed_mps, dtype=float))
    if np.ptp(v) <= 1e-9 * v.mean():
        return np.array([wheelbase_m / v.mean()]), np.ones(1)
    weights, edges = np.histogram(wheelbase_m / v, bins=64, weights=v)
    return 0.5 * (edges[:-1] + edges[1:]), weights / weights.sum()


_ROLL_OFF = 0.1  # spatial_band's raised-cosine edge, ± this share of its end frequency


def spatial_band(freq_hz: np.ndarray, speed_mps: float | np.ndarray, max_cpm: float) -> np.ndarray:
    """The share (0..1) of the road's power at ``freq_hz`` when its profile ends at ``max_cpm``
    cycles/m: 1 below ``max_cpm v`` and 0 above, with a raised-cosine edge ±10 % wide (a
    smooth model interpolates well between its grid's nodes); all ones for ``max_cpm`` 0.

    Why: a tyre's contact patch smooths wavelengths shorter than about itself away (ISO
    8608's profiles, and the simulator's, end at 5 cycles/m), so what aliases into the band
    is the road below that frequency only. At 30 km/h (5 cycles/m: 42 Hz) nothing aliases at
    100 Hz; modelled as aliasing, the power the model put at the band's noise floors took
    3 % off the full car's roll inertia with quiet sensors. ``v`` the mean speed. The models
    apply it to the aliases only: in the band the road is kept at every frequency (its end
    falls into the default band below about 11 km/h, which is not modelled).
    """
    f = np.abs(np.asarray(freq_hz, dtype=float))
    if max_cpm <= 0:
        return np.ones(f.shape)
    end_hz = max_cpm * float(np.mean(speed_mps))
    x = np.clip((f - (1.0 - _ROLL_OFF) * end_hz) / (2.0 * _ROLL_OFF * end_hz), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * x))


def track_coherence(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(γ, dγ/dc) of the isotropic surface for ``w = 2`` at ``x = 2π n B e^c``:
    ``γ = x K₁(x)`` and, as ``d(x K₁)/dx = -x K₀``, ``dγ/dc = -x² K₀(x)``."""
    xp = np.maximum(x, 1e-300)
    with np.errstate(over="ignore", invalid="ignore"):
        gamma = np.where(x > 0, np.nan_to_num(xp * special.k1(xp), nan=0.0), 1.0)
        slope = np.where(x > 0, np.nan_to_num(-xp * xp * special.k0(xp), nan=0.0), 0.0)
    return np.clip(gamma, 0.0, 1.0), slope
