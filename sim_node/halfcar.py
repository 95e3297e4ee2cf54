"""The 4-DOF half car (thesis chapter 3) and its exact, streaming discretisation.

Generalised coordinates (eq 3-1): ``q = [x_tf, x_tr, x_s, phi]`` — front and rear
wheel heave, body heave at the centre of gravity, body pitch (positive nose up).
Body points at the axles move ``x_sf = x_s + lf*phi`` and ``x_sr = x_s - lr*phi``
(eqs 3-8, 3-9; the thesis prints ``l_f`` in 3-9 and in the rear damping term of 3-6,
both typos corrected here).

The road enters through the tyres as displacement and velocity; the model is discretised
exactly (first-order hold) and propagated block by block in modal coordinates by
:mod:`sim_node.modal`, so a long run equals the concatenation of blocks.

Departures from the linear model (:mod:`sim_node.departures`), both off by default: a
nonlinear suspension and delayed sensors, run by :class:`sim_node.plant.SuspendedPlant`.
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.gravity import gravity_height_m, rotation_inertia_kgm2, rotation_stiffness_nmprad
from rozyn_estimator.vehicle import Vehicle
from sim_node.departures import SuspensionLaw
from sim_node.modal import SecondOrderModel, StateSpace, natural_modes_of, state_space_of, static_state_of
from sim_node.plant import SuspendedPlant

N_DOF = 4
N_STATE = 2 * N_DOF


def second_order_model(v: Vehicle) -> SecondOrderModel:
    """Mass, damping and stiffness matrices of eqs 3-4 to 3-7 (typos corrected), with the weight
    through the geometry on pitch where the vehicle gives its heights (:mod:`rozyn_estimator.gravity`)."""
    lf, lr = v.cog_from_front_axle_m, v.cog_from_rear_axle_m

    def suspension_matrix(kf: float, kr: float, tf: float, tr: float) -> np.ndarray:
        # Same pattern for stiffness (eq 3-5) and damping (eq 3-6): suspension element
        # between wheel and body point, tyre element between road and wheel.
        return np.array(
            [
                [tf + kf, 0.0, -kf, -lf * kf],
                [0.0, tr + kr, -kr, lr * kr],
                [-kf, -kr, kf + kr, lf * kf - lr * kr],
                [-lf * kf, lr * kr, lf * kf - lr * kr, lf**2 * kf + lr**2 * kr],
            ]
        )

    stiffness = suspension_matrix(
        v.suspension_stiffness_front_npm,
        v.suspension_stiffness_rear_npm,
        v.tyre_stiffness_front_npm,
        v.tyre_stiffness_rear_npm,
    )
    damping = suspension_matrix(
        v.suspension_damping_front_nspm,
        v.suspension_damping_rear_nspm,
        v.tyre_damping_front_nspm,
        v.tyre_damping_rear_nspm,
    )
    mass = np.diag(
        [v.unsprung_mass_front_kg, v.unsprung_mass_rear_kg, v.sprung_mass_kg, v.pitch_inertia_kgm2]
    )
    h = gravity_height_m(v)  # the weight through the geometry (0 where the heights are not given)
    stiffness[3, 3] += rotation_stiffness_nmprad(v.sprung_mass_kg, h)
    unsprung_kg = v.unsprung_mass_front_kg + v.unsprung_mass_rear_kg
    mass[3, 3] += rotation_inertia_kgm2(v.sprung_mass_kg, h, unsprung_kg)[0]
    tyre_k = np.zeros((N_DOF, 2))
    tyre_k[0, 0], tyre_k[1, 1] = v.tyre_stiffness_front_npm, v.tyre_stiffness_rear_npm
    tyre_c = np.zeros((N_DOF, 2))
    tyre_c[0, 0], tyre_c[1, 1] = v.tyre_damping_front_nspm, v.tyre_damping_rear_nspm
    return SecondOrderModel(mass, damping, stiffness, tyre_k, tyre_c)


def sensor_rows(v: Vehicle) -> np.ndarray:
    """(2, 4) map from ``q`` to the body's vertical motion at the two sensors."""
    lf = v.cog_from_front_axle_m
    rows = np.zeros((2, N_DOF))
    for i, x in enumerate(v.sensor_x_m):
        rows[i, 2] = 1.0
        rows[i, 3] = lf - x
    return rows


def suspension_rows(v: Vehicle) -> np.ndarray:
    """(2, 4) map ``G`` from ``q`` to the corners' extensions ``e = x_s,axle - x_t`` (eqs 3-8,
    3-9): the suspension part of eq 3-5 is ``G^T diag(k_s) G``, of eq 3-6 ``G^T diag(c_s) G``."""
    lf, lr = v.cog_from_front_axle_m, v.cog_from_rear_axle_m
    return np.array([[-1.0, 0.0, 1.0, lf], [0.0, -1.0, 1.0, -lr]])


def state_space(v: Vehicle) -> StateSpace:
    """Continuous state space of the half car with road displacement as input."""
    return state_space_of(second_order_model(v), sensor_rows(v))


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
                         x0=x0, u0=u0, suspension=suspension, delays_s=delays_s, what="half-car")


def free_decay(vehicle: Vehicle, x0: np.ndarray, dt_s: float, n: int) -> np.ndarray:
    """Sensor accelerations of the free decay from state ``x0`` on a flat road."""
    return HalfCarPlant(vehicle, dt_s, x0=x0).run(np.zeros((n, 2)))


def natural_modes(v: Vehicle) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], damping ratio) of the four modes, sorted by frequency."""
    return natural_modes_of(state_space(v))
