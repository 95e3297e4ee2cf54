"""The corner values' derivative rows of the half car's spectrum, all rows at once (and the
sensors', :func:`sensor_dg`).

A corner is the suspension ``z_s = k_s + iω c_s`` on the wheel ``m_t`` on the tyre
``z_t = k_t + iω c_t``; condensed, it acts on the body with ``Z = z_s W / d`` and passes
the road with ``T = z_s z_t / d`` (``W = z_t - ω² m_t``, ``d = z_s + W``; see ``model``).
A log scale factor on one of its five values moves ``z_s``, ``z_t`` or ``W`` and so

    ∂Z = (W/d)² ∂z_s + (z_s/d)² ∂W,   ∂T = z_t W/d² ∂z_s + z_s/d ∂z_t - z_s z_t/d² ∂W,

and, as ``∂Z``, ``∂T`` touch only their corner's entry, ``∂g_c = Q_k (∂T C_ck - ∂Z x_ck)``
(``Q_k`` column k of ``iω P H``).
The rows are computed as one stack (the self-calibration asks for ten of them at every
update: a loop per row cost several times more).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

CORNERS = ("front", "rear")


@dataclass(frozen=True)
class CornerState:
    """One evaluation's corners on the aliased grid: values (2,) per corner, impedances (F, 2)."""

    ks: np.ndarray  # suspension stiffness [N/m]
    cs: np.ndarray  # suspension damping [N s/m]
    kt: np.ndarray  # tyre stiffness [N/m]
    ct: np.ndarray  # tyre damping [N s/m]
    mt: np.ndarray  # unsprung mass [kg]
    zs: np.ndarray  # suspension impedance
    zt: np.ndarray  # tyre impedance
    wt: np.ndarray  # tyre impedance minus the wheel's inertia
    den: np.ndarray  # zs + wt


def corner_outer(
    state: CornerState, rows: list[tuple[str, int]], omega: np.ndarray, Q: np.ndarray,
    inputs: np.ndarray, x: np.ndarray, g: np.ndarray,
) -> np.ndarray:
    """``Σ_c ∂g_c g_cᴴ`` for each (term, corner index) row: (R, F, 2, 2).

    Args:
        state: the corners at θ.
        rows: the scaled value (``stiffness``, ``damping``, ``tyre_stiffness``,
            ``tyre_damping``, ``unsprung_mass``) and its corner (0 front, 1 rear).
        omega: (F,) angular frequencies [rad/s].
        Q: (2, 2, F) ``iω P H``.
        inputs: (C, 2, F) the road input columns ``C_c``.
        x: (C, 2, F) the axle responses ``x_c``.
        g: (C, 2, F) the sensors' responses ``g_c``.
    """
    iw = 1j * omega
    zs, zt, wt, den = state.zs, state.zt, state.wt, state.den
    by_zs = ((wt / den) ** 2, zt * wt / den**2)  # (∂Z, ∂T) per unit ∂z_s, (F, 2)
    by_zt, by_w = zs / den, ((zs / den) ** 2, zs * zt / den**2)  # ∂T per ∂z_t; (∂Z, -∂T) per ∂W
    dZ = np.empty((len(rows), omega.size), dtype=complex)
    dT = np.empty_like(dZ)
    for r, (term, c) in enumerate(rows):  # a few vector operations per row
        if term in ("stiffness", "damping"):
            dzs = state.ks[c] if term == "stiffness" else iw * state.cs[c]
            dZ[r], dT[r] = dzs * by_zs[0][:, c], dzs * by_zs[1][:, c]
        else:
            dzt = {"tyre_stiffness": state.kt[c], "tyre_damping": iw * state.ct[c]}.get(term, 0.0)
            dW = dzt if term != "unsprung_mass" else -omega**2 * state.mt[c]
            dZ[r], dT[r] = by_w[0][:, c] * dW, by_zt[:, c] * dzt - by_w[1][:, c] * dW
    k = [c for _, c in rows]
    drive = dT[:, None] * inputs[:, k].swapaxes(0, 1) - dZ[:, None] * x[:, k].swapaxes(0, 1)  # (R, C, F)
    h = np.einsum("rcf,cbf->rbf", drive, g.conj())  # Σ_c drive_c g_cᴴ, (R, 2, F)
    return (Q[:, k].transpose(1, 0, 2)[:, :, None, :] * h[:, None]).transpose(0, 3, 1, 2)


def sensor_map(x_m: np.ndarray, wheelbase_m: float, pitch_gyro: bool) -> np.ndarray:
    """P (2, 2): axle motion -> each channel's row: heave at an accelerometer's ``x``; a pitch gyro's
    pitch ``(x_sf - x_sr) / L`` (its rate: :func:`gyro_factor`)."""
    P = np.column_stack([1.0 - x_m / wheelbase_m, x_m / wheelbase_m])
    if pitch_gyro:
        P[1] = np.array([1.0, -1.0]) / wheelbase_m
    return P


def gyro_factor(omega: np.ndarray) -> np.ndarray:
    """A pitch gyro's factor on its row of ``iω P x`` (an acceleration): ``gyro_y = -φ' = -φ''/(iω)``
    (REP 103: positive nose down)."""
    return np.divide(1j, omega, out=np.zeros(omega.shape, complex), where=omega != 0)


def sensor_dg(model: Any, want: set[str], x: list[np.ndarray], g: list[np.ndarray], iw: np.ndarray,
              rear: np.ndarray | None) -> dict[str, list[np.ndarray]]:
    """``∂g_c`` by the sensors' positions, the rear's gain and its delay (those of the model's
    θ in ``want``), per input column ``c``: the sensor rows of ``iω P x``."""
    zero, rows = np.zeros_like(iw), {}
    for a, name in enumerate(("sensor_front_x_m", "sensor_rear_x_m")):
        if name in model.index and name in want and not (a == 1 and model.pitch_gyro):  # a gyro has no x
            # ∂g_a/∂x_a = iω [-1/L, 1/L] x (and the rear factor)
            dP = np.array([-1.0, 1.0]) / model.wheelbase_m
            factor = rear if a == 1 and rear is not None else 1.0
            rows[name] = [np.array([iw * (dP @ xc), zero])[:: 1 if a == 0 else -1] * factor for xc in x]
    if "ln_rear_gain" in model.index and "ln_rear_gain" in want:  # ∂g_r/∂ln(gain) = g_r
        rows["ln_rear_gain"] = [np.array([zero, gc[1]]) for gc in g]
    if "time_offset_ms" in model.index and "time_offset_ms" in want:  # ∂g_r/∂τ = -iω g_r (τ in ms)
        rows["time_offset_ms"] = [np.array([zero, -1e-3 * iw * gc[1]]) for gc in g]
    return rows
