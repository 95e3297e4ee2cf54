"""The 4-DOF half car (thesis chapter 3) and its exact, streaming discretisation.

Generalised coordinates (eq 3-1): ``q = [x_tf, x_tr, x_s, phi]`` — front and rear
wheel heave, body heave at the centre of gravity, body pitch (positive nose up).
Body points at the axles move ``x_sf = x_s + lf*phi`` and ``x_sr = x_s - lr*phi``
(eqs 3-8, 3-9; the thesis prints ``l_f`` in 3-9 and in the rear damping term of 3-6,
both typos corrected here).

The matrices are :mod:`rozyn_estimator.body_model`'s (the estimator's too).
The road enters through the tyres as displacement and velocity; the model is discretised
exactly (first-order hold) and propagated block by block in modal coordinates by
:mod:`sim_node.modal`, so a long run equals the concatenation of blocks.

Departures from the linear model (:mod:`sim_node.departures`), both off by default: a
nonlinear suspension and delayed sensors, run by :class:`sim_node.plant.SuspendedPlant`.
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.body_model import HALF_DOF as N_DOF
from rozyn_estimator.body_model import half_car_model as second_order_model
from rozyn_estimator.body_model import half_car_sensor_rates as sensor_rates
from rozyn_estimator.body_model import half_car_sensor_rows as sensor_rows
from rozyn_estimator.body_model import half_car_suspension_rows as suspension_rows
from rozyn_estimator.vehicle import Vehicle
from sim_node.departures import SuspensionLaw
from sim_node.modal import StateSpace, natural_modes_of, state_space_of, static_state_of
from sim_node.plant import SuspendedPlant

N_STATE = 2 * N_DOF


def state_space(v: Vehicle) -> StateSpace:
    """Continuous state space of the half car with road displacement as input."""
    return state_space_of(second_order_model(v), sensor_rows(v), sensor_rates(v))


def static_state(v: Vehicle, road_m: np.ndarray) -> np.ndarray:
    """State ``x`` at rest on a road held at ``road_m = [front, rear]`` [m]."""
    return static_state_of(second_order_model(v), road_m)


class HalfCarPlant(SuspendedPlant):
    """Exact-discretised half car, propagated block by block.

    Args:
        vehicle: the vehicle.
        dt_s: simulation step [s]; the road is piecewise linear between steps.
        x0: initial physical state ``[q, q']`` (default: at rest, zero road).
        u0: road displacement at the first step, for the state shift [m].
        suspension: the suspension's nonlinear part (None: the linear eqs 3-5, 3-6).
        delays_s: (front, rear) delay of each output behind its step [s], >= 0
            (:class:`sim_node.plant.SuspendedPlant`).
    """

    def __init__(
        self,
        vehicle: Vehicle,
        dt_s: float,
        x0: np.ndarray | None = None,
        u0: np.ndarray | None = None,
        suspension: SuspensionLaw | None = None,
        delays_s: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        self.vehicle = vehicle
        super().__init__(second_order_model(vehicle), sensor_rows(vehicle), suspension_rows(vehicle), dt_s,
                         x0=x0, u0=u0, suspension=suspension, delays_s=delays_s, what="half-car",
                         rates=sensor_rates(vehicle))


def free_decay(vehicle: Vehicle, x0: np.ndarray, dt_s: float, n: int) -> np.ndarray:
    """What the sensors read (accelerations; a gyro's rate) in the free decay from ``x0`` on a flat road."""
    return HalfCarPlant(vehicle, dt_s, x0=x0).run(np.zeros((n, 2)))


def natural_modes(v: Vehicle) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], damping ratio) of the four modes, sorted by frequency."""
    return natural_modes_of(state_space(v))


__all__ = ["N_DOF", "N_STATE", "HalfCarPlant", "free_decay", "natural_modes", "second_order_model",
           "sensor_rates", "sensor_rows", "state_space", "static_state", "suspension_rows"]
