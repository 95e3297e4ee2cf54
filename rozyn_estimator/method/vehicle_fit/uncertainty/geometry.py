"""The full car's spectrum's derivatives in its geometry, the wheelbase and the tracks, for the
first-order budget (:mod:`.refine_budget`): one batched pass of the model's own pieces instead
of a model evaluation per value.

Where the geometry enters the model (:mod:`..spectrum`):

- the corners' positions in the body map ``B`` (the rear corners at ``x = L``, an axle's two
  at ``y = ±t/2``): ``D = Bᵀ Z B - ω² M`` and the road's input ``Bᵀ T`` move, so
  ``dH = D⁻¹ (dBᵀ (T - Z B H) - Bᵀ Z dB H)`` and ``d(P H R Hᴴ Pᴴ) = P dH R Hᴴ Pᴴ + h.c.``;
- an anti-roll bar's stiffness at the corners, ``K/t²`` (a change of the bar's value ``K`` by
  ``-2K/t`` per metre of track: :meth:`~.spectrum.VehicleSpectrum.corner_derivatives`);
- the rear wheels' delay behind the front ones (the wheelbase:
  :func:`~rozyn_estimator.method.likelihood.road_input.delay_slope` in ``R``);
- the tracks' coherence, whose argument is proportional to the front track
  (``dγ/dt = (dγ/dc) / t``, ``c`` the coherence's log scale).

The sensors' positions are the vehicle's own (measured from the front axle and the
centreline), and θ's scale of ``l_f`` stays the model's: neither moves.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from rozyn_estimator.method.likelihood.road_input import delay_slope, track_coherence
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.stacks import herm

GEOMETRY = ("wheelbase_m", "track_front_m", "track_rear_m")
_BAR = {"track_front_m": (20, "anti_roll_stiffness_front_nmprad"),
        "track_rear_m": (21, "anti_roll_stiffness_rear_nmprad")}  # the bar's column among the corner values


def geometry_derivatives(model: VehicleSpectrum, theta: np.ndarray, keys: Sequence[str]) -> np.ndarray:
    """dS (G, nodes, k, k) at θ per metre of each of ``keys`` (of :data:`GEOMETRY`); on a varying
    drive (the road's mixture over the window's delays and speeds) by central differences."""
    v = model.vehicle
    if not v.ROLLS:
        raise TypeError("the geometry's derivatives are the full car's (the half car's budget is its own)")
    if model.mixture is not None:
        return np.array([_difference(model, theta, key) for key in keys])
    inv_d, H, inputs, _, d_motion = model.body_motion(theta)
    sensing = model.sensing_at(theta)
    B = model.body_map
    Z, T = model.corner_impedance
    d_map = np.zeros((len(keys), 4, 3))  # dB per metre
    for g, key in enumerate(keys):
        if key == "wheelbase_m":
            d_map[g, 2:, 1] = -1.0
        elif key in _BAR:
            d_map[g, (0, 1) if key == "track_front_m" else (2, 3), 2] = (0.5, -0.5)
        else:
            raise ValueError(f"{key} is not a geometry value ({', '.join(GEOMETRY)})")
    d_t = d_map.swapaxes(-1, -2)[:, None]  # (G, 1, 3, 4)
    d_h = inv_d @ (d_t @ (T - Z @ (B @ H)) - (B.T @ Z) @ (d_map[:, None] @ H))  # (G, F, 3, 4)
    part = sensing @ d_h @ (inputs @ herm(H) @ herm(sensing))
    part = part + herm(part)
    for g, key in enumerate(keys):
        if key == "wheelbase_m":
            slope = delay_slope(model.omega, v.wheelbase_m, model.speed_mps)
            zero = np.zeros_like(slope)
            d_delay = np.stack([zero, slope.conj(), slope, zero], axis=-1).reshape(-1, 2, 2)
            gamma, _ = track_coherence(model.x_coherence * np.exp(theta[model.index["ln_coherence_scale"]]))
            d_inputs = model.road_weight(theta)[:, None, None] * model.road_inputs(gamma, delay=d_delay)
            part[g] += sensing @ H @ d_inputs @ herm(H) @ herm(sensing)
        elif key == "track_front_m":
            part[g] += sensing @ d_motion @ herm(sensing) / v.coherence_track_m  # the coherence's scale
    out = model.fold(part)
    bars = [(g, *_BAR[key], getattr(v, key)) for g, key in enumerate(keys)
            if key in _BAR and getattr(v, _BAR[key][1]) != 0]
    if bars:
        directions = np.zeros((len(bars), 22))
        for j, (_, column, bar, track) in enumerate(bars):
            directions[j, column] = -2.0 * getattr(v, bar) / track  # d(K/t²)/dt = -2K/t³
        out[[g for g, *_ in bars]] += model.corner_derivatives(theta, directions)
    return out


def _difference(model: VehicleSpectrum, theta: np.ndarray, key: str, step: float = 1e-5) -> np.ndarray:
    """dS/d(key) at θ by a central difference of the model (a varying drive's mixture moves with
    the wheelbase's delays and the track's coherence at each of its speeds)."""
    ends = []
    for sign in (1.0, -1.0):
        moved = dataclasses.replace(model.vehicle, **{key: getattr(model.vehicle, key) + sign * step})
        with model.assuming(moved):
            ends.append(model.node_spectrum(theta, derivatives=False)[0])
    return (ends[0] - ends[1]) / (2.0 * step)
