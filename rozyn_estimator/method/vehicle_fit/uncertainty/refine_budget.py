"""What each toleranced value contributes to the full car's refined estimate (GUM type B).

An assumed value ``β`` off by ``δ`` moves the likelihood's optimum by
``dθ̂ = -F⁻¹ F_θβ δ``, ``F_θβ = Σ_k tr(S⁻¹ ∂_θ S S⁻¹ ∂_β S)`` the information shared between the
fitted parameters and ``β`` (the expected score's slope in ``β``: the fit absorbs what it can
of the changed spectrum into θ, the nuisances included). ``∂_β S``: for the corners' values
(springs, dampers, tyres, unsprung masses, bars) and the sensors' positions, gains and
timing the model's analytic derivatives (:class:`~rozyn_estimator.method.vehicle_fit.spectrum.
VehicleSpectrum`'s ``corner_derivatives`` and ``sensing_derivatives``, and for the wheelbase
and tracks :func:`~.geometry.geometry_derivatives`, each in one pass); for any other value the
model's change with the value moved a small step.
Per toleranced value: that move times its tolerance,
mapped to ``(m, I_xx, I_yy, l_f, y_c)``. The keys follow the Rozyn stage's budget
(:func:`rozyn_estimator.method.vehicle_fit.uncertainty.moves.vehicle_moves`): an axle's share applies
to both its corners,
a sensor's position or gain to each sensor on its own (independent errors: one
contribution each), the time offset to the rear sensors against the front ones.

Work: ``F_θβ`` is summed as the optimiser's Hessian is, over every 3rd frequency, each
counting for its neighbours (:meth:`~.whittle.WhittleObjective.sampled_rows`: it is smooth in
frequency; measured within 1.3 % of the whole sum, the budget's total within 0.6 %), all
moves whitened in one pass; a stepped move is one evaluation of S without derivatives on
the model's evaluation grid (:mod:`..grid`). Measured: the budget of a cold update from 76 ms
to about 20, then (the sampled sum) by a further ~10 ms, then (the geometry's derivatives
instead of three stepped evaluations) to about 2.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.uncertainty.geometry import GEOMETRY, geometry_derivatives
from rozyn_estimator.method.vehicle_fit.uncertainty.moves import (
    ABS_STEP,
    VehicleMove,
    axle_channels,
    shifted_sensor,
    values_of,
    vehicle_moves,
)
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective

# a move: the step -> (the vehicle moved, a factor per channel (F, k) or None)
Move = Callable[[float], tuple[AnyVehicle, np.ndarray | None]]


def refinement_contributions(objective: WhittleObjective, theta: np.ndarray, theta_cov: np.ndarray,
                             vehicle: AnyVehicle, skip: set[str] | None = None) -> dict[str, np.ndarray]:
    """Contributions ``c_j`` (5,) of each toleranced value of ``vehicle`` to the refined estimate
    (but those of the tolerance keys in ``skip``: the calibrated sensors')."""
    model = objective.model
    _, linv = objective.factored(theta)
    S = objective.node_spectrum(theta)
    jac = model.physical_jacobian(theta)
    moves = [(name, step, move(step), tol) for key, tol in vehicle.tolerances.applying(vehicle).items()
             if key not in (skip or set()) for name, step, move in _moves(vehicle, model, key)]
    order = [name for name, *_ in moves]
    changes: dict[str, np.ndarray] = {}  # name -> dS along the move, per unit step
    corner_moves = [(m[0], d) for m in moves if (d := _corner_direction(vehicle, *m[2], m[1])) is not None]
    if corner_moves:
        derivatives = model.corner_derivatives(theta, np.array([d for _, d in corner_moves]))
        changes.update(zip([name for name, _ in corner_moves], derivatives, strict=True))
    sensor_moves = [(m[0], d) for m in moves if m[0] not in changes
                    and (d := _sensor_change(model, vehicle, *m[2], m[1])) is not None]
    if sensor_moves:
        derivatives = model.sensing_derivatives(theta, np.array([d for _, d in sensor_moves]))
        changes.update(zip([name for name, _ in sensor_moves], derivatives, strict=True))
    geometry = [name for name in order if name in GEOMETRY and name not in changes] \
        if vehicle.ROLLS else []  # the half car's: stepped
    if geometry:
        changes.update(zip(geometry, geometry_derivatives(model, theta, geometry), strict=True))
    for name, step, (moved, factor), _ in moves:
        if name not in changes:
            with model.assuming(moved, factor):
                changes[name] = (model.node_spectrum(theta, derivatives=False)[0] - S) / step
    if not changes:
        return {}
    tols = {name: tol for name, _, _, tol in moves}
    rows = objective.sampled_rows(theta)
    shared = rows @ objective.sampled(np.array([changes[name] for name in order]), linv).T  # F_θβ
    per_unit = -(jac @ (theta_cov @ shared))  # (5, moves)
    return {name: per_unit[:, j] * tols[name] for j, name in enumerate(order)}


def _corner_direction(base: AnyVehicle, moved: AnyVehicle, factor: np.ndarray | None,
                      step: float) -> np.ndarray | None:
    """The move's change of the corners' values per unit step (:func:`.moves.values_of`), or
    None when it moves anything else."""
    if factor is not None or not _moves_only(base, moved, base.CORNER_FIELDS):
        return None
    return (values_of(moved) - values_of(base)) / step


def _sensor_change(model: VehicleSpectrum, base: AnyVehicle, moved: AnyVehicle, factor: np.ndarray | None,
                   step: float) -> np.ndarray | None:
    """(F, k, b) the move's change of the sensing per unit step, or None when it moves
    anything but the sensors' positions (and their channels' factors)."""
    if not _moves_only(base, moved, base.SENSOR_FIELDS):
        return None
    return (model.sensing_of(moved, factor) - model.sensing) / step


def _moves_only(base: AnyVehicle, moved: AnyVehicle, names: tuple[str, ...]) -> bool:
    """``moved`` (a :func:`moved_copy` of ``base``) holds ``base``'s own values but ``names``."""
    return all(getattr(moved, f.name) is getattr(base, f.name) for f in dataclasses.fields(base)
               if f.name not in names)


def _moves(v: AnyVehicle, model: VehicleSpectrum, key: str) -> list[tuple[str, float, Move]]:
    """(contribution name, step, the move) of one tolerance key: the vehicle's values as in
    Rozyn's stage's budget; each sensor's offset and gain on its own, the rear sensors' timing
    as a factor on their channels."""
    def unsensed(move: VehicleMove) -> Move:
        return lambda h: (move(h), None)

    def shifted(channel: int) -> Move:
        return lambda h: (shifted_sensor(v, channel, h), None)

    def channel(columns: list[int], factor: Callable[[float], np.ndarray]) -> Move:
        def move(h: float) -> tuple[AnyVehicle, np.ndarray | None]:
            out = np.ones((model.omega.size, model.k), dtype=complex)
            out[:, columns] = factor(h)[:, None]
            return v, out
        return move

    sensors = model.sensors
    alike = vehicle_moves(v, key, sensors)
    if alike is not None:
        return [(name, step, unsensed(move)) for name, step, move in alike]
    axle = axle_channels(v, "front" if "_front" in key else "rear")
    if key in ("sensor_front_offset_m", "sensor_rear_offset_m"):
        return [(f"{key}[{v.channel_names[c]}]", ABS_STEP, shifted(c)) for c in sensors
                if c in axle and v.channel_kinds[c] == "accel_z"]  # a gyro reads the same anywhere
    if key.startswith("sensor_gain"):
        return [(f"{key}[{v.channel_names[c]}]", ABS_STEP,
                 channel([j], lambda h: np.full(model.omega.size, 1.0 + h, dtype=complex)))
                for j, c in enumerate(sensors) if c in axle]
    if key == "sensor_time_offset_s":
        rear = [j for j, c in enumerate(sensors) if v.channel_late[c]]
        return [(key, ABS_STEP, channel(rear, lambda h: np.exp(-1j * model.omega * h)))] if rear else []
    return []
