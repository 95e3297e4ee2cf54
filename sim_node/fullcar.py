"""The 7-DOF full car and its exact, streaming discretisation.

The half car of thesis chapter 3 widened to four corners (the thesis names a bigger model
as the way to more parameters, chapter 3). Generalised coordinates
``q = [x_t,FL, x_t,FR, x_t,RL, x_t,RR, x_s, phi, theta]``: the four wheels' heave, the
body's heave at its centre of gravity, pitch (positive nose up, as the half car) and roll
(positive left side up: REP 103's roll about +x forward). Coordinates and the corner order
are :mod:`rozyn_estimator.vehicle_full`'s: ``x`` behind the front axle, ``y`` positive left.

A body point at ``(x, y)`` moves, for small angles (eqs 3-8, 3-9 widened),
``z(x, y) = x_s + (lf - x) phi + (y - y_cog) theta``. Each corner's suspension
(stiffness, damping) acts between the body point above its wheel and the wheel, its tyre
(stiffness, damping) between the wheel and the road under it; an anti-roll bar of roll
stiffness ``K`` [N*m/rad] acts on the difference of its axle's two suspension extensions,
``K / track^2`` N/m between them. With ``G`` the (4, 7) map from ``q`` to the extensions
``e = z(corner) - x_t``::

    M = diag(m_t, m_s, I_yy, I_xx)                                   (eq 3-4 widened)
    K = diag(k_t, 0, 0, 0) + G^T diag(k_s) G + sum_axles (K_arb / t^2) G^T a a^T G  (eq 3-5)
    C = diag(c_t, 0, 0, 0) + G^T diag(c_s) G                         (eq 3-6)

with ``a = [1, -1, 0, 0]`` (front) or ``[0, 0, 1, -1]`` (rear), and, where the vehicle gives
its heights, the weight through the geometry on pitch and roll (:mod:`rozyn_estimator.gravity`:
``-m g h`` on their stiffness, ``μ h²`` on their inertia). The road under the four
tyres enters as displacement (``k_t``) and velocity (``c_t``), and the model is
discretised exactly (first-order hold) and propagated in modal blocks by :mod:`sim_node.modal`,
as the half car is. The matrices are :mod:`rozyn_estimator.body_model`'s (the estimator's too).

The departures (:mod:`sim_node.departures`) as the half car's: a nonlinear suspension at
each corner (the anti-roll bars stay linear) and delayed sensors, run by
:class:`sim_node.plant.SuspendedPlant`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.body_model import FULL_CORNERS as N_TYRES
from rozyn_estimator.body_model import FULL_DOF as N_DOF
from rozyn_estimator.body_model import FULL_HEAVE as HEAVE
from rozyn_estimator.body_model import FULL_PITCH as PITCH
from rozyn_estimator.body_model import FULL_ROLL as ROLL
from rozyn_estimator.body_model import full_car_body_rows as body_rows
from rozyn_estimator.body_model import full_car_model as second_order_model
from rozyn_estimator.body_model import full_car_sensor_points as sensor_points
from rozyn_estimator.body_model import full_car_sensor_rates as sensor_rates
from rozyn_estimator.body_model import full_car_sensor_rows as sensor_rows
from rozyn_estimator.body_model import full_car_suspension_rows as suspension_rows
from rozyn_estimator.vehicle_full import FullVehicle
from sim_node.departures import SuspensionLaw
from sim_node.modal import StateSpace, natural_modes_of, state_space_of, static_state_of
from sim_node.plant import SuspendedPlant

N_STATE = 2 * N_DOF


def state_space(v: FullVehicle, points_m: np.ndarray | None = None) -> StateSpace:
    """Continuous state space, road displacement (FL, FR, RL, RR) in, the body's vertical
    acceleration at ``points_m`` (k, 2) out (default: the vehicle's channels)."""
    if points_m is None:
        return state_space_of(second_order_model(v), sensor_rows(v), sensor_rates(v))
    return state_space_of(second_order_model(v), body_rows(v, points_m))


def static_state(v: FullVehicle, road_m: np.ndarray) -> np.ndarray:
    """State ``x = [q, q']`` at rest on a road held at ``road_m`` (FL, FR, RL, RR) [m]."""
    return static_state_of(second_order_model(v), road_m)


class FullCarPlant(SuspendedPlant):
    """Exact-discretised full car, propagated block by block.

    Args:
        vehicle: the vehicle.
        dt_s: simulation step [s]; the road is piecewise linear between steps.
        x0: initial physical state ``[q, q']`` (14,) (default: at rest, zero road).
        u0: road displacement (FL, FR, RL, RR) at the first step, for the state shift [m].
        points_m: (k, 2) body points ``(x, y)`` whose vertical acceleration is the output
            (default: the vehicle's channels: the four accelerometers, FL, FR, RL, RR, or a
            sensors block's, its gyros reading rates).
        suspension: the suspension's nonlinear part, per corner (None: linear).
        delays_s: each output's delay behind its step [s], >= 0 (empty: none).

    Example:
        >>> plant = FullCarPlant(FullVehicle(), dt_s=0.002)
        >>> plant.run(np.full((3, 4), 0.01)).shape  # a 1 cm step under all four tyres
        (3, 4)
    """

    def __init__(self, vehicle: FullVehicle, dt_s: float, x0: np.ndarray | None = None,
                 u0: np.ndarray | None = None, points_m: np.ndarray | None = None,
                 suspension: SuspensionLaw | None = None, delays_s: Sequence[float] = ()) -> None:
        self.vehicle = vehicle
        rows = sensor_rows(vehicle) if points_m is None else body_rows(vehicle, points_m)
        rates = sensor_rates(vehicle) if points_m is None else None
        super().__init__(second_order_model(vehicle), rows, suspension_rows(vehicle),
                         dt_s, x0=x0, u0=u0, suspension=suspension, delays_s=delays_s, what="full-car",
                         rates=rates)


def free_decay(vehicle: FullVehicle, x0: np.ndarray, dt_s: float, n: int) -> np.ndarray:
    """Accelerations at the accelerometers in the free decay from state ``x0`` on a flat road."""
    return FullCarPlant(vehicle, dt_s, x0=x0).run(np.zeros((n, N_TYRES)))


def natural_modes(v: FullVehicle) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], damping ratio) of the seven modes, sorted by frequency."""
    return natural_modes_of(state_space(v))


__all__ = ["HEAVE", "N_DOF", "N_STATE", "N_TYRES", "PITCH", "ROLL", "FullCarPlant", "body_rows", "free_decay",
           "natural_modes", "second_order_model", "sensor_points", "sensor_rates", "sensor_rows",
           "state_space", "static_state", "suspension_rows"]
