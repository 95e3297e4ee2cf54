"""The simulated vehicle: :mod:`rozyn_estimator.body_model`'s body on its corners, discretised
exactly and run block by block.

One plant for every vehicle the body model describes: the half car (thesis chapter 3, its two
corners on the centreline; ``q = [x_tf, x_tr, x_s, phi]``) and the full car (four corners and
anti-roll bars; ``q = [x_t,FL, x_t,FR, x_t,RL, x_t,RR, x_s, phi, theta]``). The matrices are
the body model's, which the estimator shares. The road under each tyre enters as displacement
and velocity; the model is discretised exactly (first-order hold) and propagated in modal
blocks (:mod:`sim_node.modal`), so a long run equals the concatenation of blocks. The
departures (:mod:`sim_node.departures`: a nonlinear suspension at each corner, the anti-roll
bars staying linear, and delayed sensors) are :class:`sim_node.plant.SuspendedPlant`'s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.body_model import (
    AnyVehicle,
    body_rows,
    corner_count,
    dof,
    second_order_model,
    sensor_rates,
    sensor_rows,
    suspension_rows,
)
from sim_node.departures import SuspensionLaw
from sim_node.modal import StateSpace, natural_modes_of, state_space_of, static_state_of
from sim_node.plant import SuspendedPlant


def n_state(v: AnyVehicle) -> int:
    """The length of the plant's physical state ``[q, q']``."""
    return 2 * dof(v)


def state_space(v: AnyVehicle, points_m: np.ndarray | None = None) -> StateSpace:
    """Continuous state space, the road under each tyre in, the channels out (default: the
    vehicle's; a gyro reads its rate) or the body's vertical acceleration at ``points_m`` (k, 2)."""
    if points_m is None:
        return state_space_of(second_order_model(v), sensor_rows(v), sensor_rates(v))
    return state_space_of(second_order_model(v), body_rows(v, points_m))


def static_state(v: AnyVehicle, road_m: np.ndarray) -> np.ndarray:
    """State ``x = [q, q']`` at rest on a road held at ``road_m`` (one height per tyre) [m]."""
    return static_state_of(second_order_model(v), road_m)


class VehiclePlant(SuspendedPlant):
    """The vehicle, exact-discretised and propagated block by block.

    Args:
        vehicle: the vehicle (half car or full car).
        dt_s: simulation step [s]; the road is piecewise linear between steps.
        x0: initial physical state ``[q, q']`` (default: at rest, zero road).
        u0: road displacement under each tyre at the first step, for the state shift [m].
        points_m: (k, 2) body points ``(x, y)`` whose vertical acceleration is the output
            (default: the vehicle's channels, its gyros reading rates).
        suspension: the suspension's nonlinear part, per corner (None: linear).
        delays_s: each output's delay behind its step [s], >= 0 (empty: none).

    Example:
        >>> from rozyn_estimator.vehicle_full import FullVehicle
        >>> plant = VehiclePlant(FullVehicle(), dt_s=0.002)
        >>> plant.run(np.full((3, 4), 0.01)).shape  # a 1 cm step under all four tyres
        (3, 4)
    """

    def __init__(self, vehicle: AnyVehicle, dt_s: float, x0: np.ndarray | None = None,
                 u0: np.ndarray | None = None, points_m: np.ndarray | None = None,
                 suspension: SuspensionLaw | None = None, delays_s: Sequence[float] = ()) -> None:
        self.vehicle = vehicle
        rows = sensor_rows(vehicle) if points_m is None else body_rows(vehicle, points_m)
        rates = sensor_rates(vehicle) if points_m is None else None
        what = f"{corner_count(vehicle)}-corner vehicle"
        super().__init__(second_order_model(vehicle), rows, suspension_rows(vehicle), dt_s, x0=x0, u0=u0,
                         suspension=suspension, delays_s=delays_s, what=what, rates=rates)


def free_decay(vehicle: AnyVehicle, x0: np.ndarray, dt_s: float, n: int) -> np.ndarray:
    """What the channels read (accelerations; a gyro's rate) in the free decay from ``x0`` on a flat road."""
    return VehiclePlant(vehicle, dt_s, x0=x0).run(np.zeros((n, corner_count(vehicle))))


def natural_modes(v: AnyVehicle) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], damping ratio) of the vehicle's modes, sorted by frequency."""
    return natural_modes_of(state_space(v))


__all__ = ["VehiclePlant", "free_decay", "n_state", "natural_modes", "state_space", "static_state"]
