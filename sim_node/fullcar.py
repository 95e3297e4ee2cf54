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
discretised exactly (first-order hold) and propagated in modal blocks by
:mod:`sim_node.modal`, as the half car is.

The departures (:mod:`sim_node.departures`) as the half car's: a nonlinear suspension at
each corner (the anti-roll bars stay linear) and delayed sensors, run by
:class:`sim_node.plant.SuspendedPlant`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.gravity import gravity_height_m, rotation_inertia_kgm2, rotation_stiffness_nmprad
from rozyn_estimator.vehicle_full import FullVehicle
from sim_node.departures import SuspensionLaw
from sim_node.modal import SecondOrderModel, StateSpace, natural_modes_of, state_space_of, static_state_of
from sim_node.plant import SuspendedPlant

N_DOF = 7
N_STATE = 2 * N_DOF
N_TYRES = 4
HEAVE, PITCH, ROLL = 4, 5, 6  # indices of the body's coordinates in q


def suspension_rows(v: FullVehicle) -> np.ndarray:
    """(4, 7) map ``G`` from ``q`` to the corners' extensions ``e = z(corner) - x_t`` (FL, FR, RL, RR)."""
    g = np.zeros((N_TYRES, N_DOF))
    g[:, :N_TYRES] = -np.eye(N_TYRES)
    g[:, HEAVE:] = body_rows(v, np.column_stack([v.corner_x_m, v.corner_y_m]))[:, HEAVE:]
    return g


def body_rows(v: FullVehicle, points_m: np.ndarray) -> np.ndarray:
    """(k, 7) map from ``q`` to the body's vertical motion at points ``(x, y)`` (k, 2) [m]:
    ``x_s + (lf - x) phi + (y - y_cog) theta``."""
    p = np.atleast_2d(np.asarray(points_m, dtype=float))
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points_m must have shape (k, 2) of (x, y), got {np.shape(points_m)}")
    rows = np.zeros((p.shape[0], N_DOF))
    rows[:, HEAVE] = 1.0
    rows[:, PITCH] = v.cog_from_front_axle_m - p[:, 0]
    rows[:, ROLL] = p[:, 1] - v.cog_lateral_m
    return rows


def sensor_points(v: FullVehicle) -> np.ndarray:
    """(4, 2) the accelerometers' ``(x, y)`` (FL, FR, RL, RR) [m]."""
    return np.column_stack([v.sensor_x_m, v.sensor_y_m])


def second_order_model(v: FullVehicle) -> SecondOrderModel:
    """Mass, damping and stiffness matrices (see the module's docstring), tyres as inputs."""
    g = suspension_rows(v)
    bars = np.zeros((N_TYRES, N_TYRES))  # the bars' springs between the corners' extensions
    for rows, bar_nmprad, track in ((slice(0, 2), v.anti_roll_stiffness_front_nmprad, v.track_front_m),
                                    (slice(2, 4), v.anti_roll_stiffness_rear_nmprad, v.track_rear_m)):
        bars[rows, rows] = bar_nmprad / track**2 * np.array([[1.0, -1.0], [-1.0, 1.0]])

    def corners(suspension: tuple[float, ...], tyre: tuple[float, ...], extra: np.ndarray) -> np.ndarray:
        out = g.T @ (np.diag(suspension) + extra) @ g
        out[:N_TYRES, :N_TYRES] += np.diag(tyre)
        return out

    stiffness = corners(v.suspension_stiffness_npm, v.tyre_stiffness_npm, bars)
    damping = corners(v.suspension_damping_nspm, v.tyre_damping_nspm, np.zeros((N_TYRES, N_TYRES)))
    mass = np.diag([*v.unsprung_mass_kg, v.sprung_mass_kg, v.pitch_inertia_kgm2, v.roll_inertia_kgm2])
    h = gravity_height_m(v)  # the weight through the geometry, in pitch and in roll alike
    for k in (PITCH, ROLL):
        stiffness[k, k] += rotation_stiffness_nmprad(v.sprung_mass_kg, h)
        mass[k, k] += rotation_inertia_kgm2(v.sprung_mass_kg, h, sum(v.unsprung_mass_kg))[0]
    tyre_k = np.zeros((N_DOF, N_TYRES))
    tyre_k[:N_TYRES] = np.diag(v.tyre_stiffness_npm)
    tyre_c = np.zeros((N_DOF, N_TYRES))
    tyre_c[:N_TYRES] = np.diag(v.tyre_damping_nspm)
    return SecondOrderModel(mass, damping, stiffness, tyre_k, tyre_c)


def state_space(v: FullVehicle, points_m: np.ndarray | None = None) -> StateSpace:
    """Continuous state space, road displacement (FL, FR, RL, RR) in, the body's vertical
    acceleration at ``points_m`` (k, 2) out (default: the vehicle's accelerometers)."""
    points = sensor_points(v) if points_m is None else points_m
    return state_space_of(second_order_model(v), body_rows(v, points))


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
            (default: the vehicle's four accelerometers, FL, FR, RL, RR).
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
        points = sensor_points(vehicle) if points_m is None else points_m
        super().__init__(second_order_model(vehicle), body_rows(vehicle, points), suspension_rows(vehicle),
                         dt_s, x0=x0, u0=u0, suspension=suspension, delays_s=delays_s, what="full-car")


def free_decay(vehicle: FullVehicle, x0: np.ndarray, dt_s: float, n: int) -> np.ndarray:
    """Accelerations at the accelerometers in the free decay from state ``x0`` on a flat road."""
    return FullCarPlant(vehicle, dt_s, x0=x0).run(np.zeros((n, N_TYRES)))


def natural_modes(v: FullVehicle) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], damping ratio) of the seven modes, sorted by frequency."""
    return natural_modes_of(state_space(v))


__all__ = ["N_DOF", "N_STATE", "N_TYRES", "FullCarPlant", "body_rows", "free_decay", "natural_modes",
           "second_order_model", "sensor_points", "state_space", "static_state", "suspension_rows"]
