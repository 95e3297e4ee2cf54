"""The vehicle's equations of motion ``M q'' + C q' + K q = Kt u + Ct u'``: the half car (thesis
chapter 3, eqs 3-4 to 3-9, typos corrected) and the full car (the half car widened to four
corners with anti-roll bars), with the weight through the geometry where the vehicle gives its
heights (:mod:`rozyn_estimator.gravity`).

The simulator's plants (:mod:`sim_node.halfcar`, :mod:`sim_node.fullcar`) run these matrices, and
the estimator uses them for what it must predict in the time domain (the body's response to the
load transfer of accelerating and braking, :mod:`rozyn_estimator.method.load_transfer`), so the
plant and the observer share the vehicle as they share its parameters.

Half car: ``q = [x_tf, x_tr, x_s, phi]`` (wheels, body heave at the CoG, pitch positive nose up).
Full car: ``q = [x_t,FL, x_t,FR, x_t,RL, x_t,RR, x_s, phi, theta]`` (roll positive left side up);
a body point at ``(x, y)`` moves ``x_s + (lf - x) phi + (y - y_cog) theta``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.gravity import gravity_height_m, rotation_inertia_kgm2, rotation_stiffness_nmprad
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle

HALF_DOF = 4
HALF_PITCH = 3
FULL_DOF = 7
FULL_CORNERS = 4
FULL_HEAVE, FULL_PITCH, FULL_ROLL = 4, 5, 6  # the body's coordinates in the full car's q


@dataclass(frozen=True)
class SecondOrderModel:
    """``M q'' + C q' + K q = Kt u + Ct u'`` with ``u`` the road displacement under each tyre [m]."""

    mass: np.ndarray  # (dof, dof), diagonal
    damping: np.ndarray  # (dof, dof)
    stiffness: np.ndarray  # (dof, dof)
    tyre_stiffness: np.ndarray  # (dof, tyres) road displacement -> generalised force
    tyre_damping: np.ndarray  # (dof, tyres) road velocity -> generalised force

    @property
    def dof(self) -> int:
        return int(self.mass.shape[0])


def half_car_model(v: Vehicle) -> SecondOrderModel:
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
    tyre_k = np.zeros((HALF_DOF, 2))
    tyre_k[0, 0], tyre_k[1, 1] = v.tyre_stiffness_front_npm, v.tyre_stiffness_rear_npm
    tyre_c = np.zeros((HALF_DOF, 2))
    tyre_c[0, 0], tyre_c[1, 1] = v.tyre_damping_front_nspm, v.tyre_damping_rear_nspm
    return SecondOrderModel(mass, damping, stiffness, tyre_k, tyre_c)


def half_car_sensor_rows(v: Vehicle) -> np.ndarray:
    """(2, 4) map from ``q`` to what the two channels read: an accelerometer the body's vertical
    motion at its position, a pitch gyro (``gyro_y``, REP 103: positive nose down) ``-phi``; the
    gyro reads the rate of its row, an accelerometer the acceleration (:func:`half_car_sensor_rates`)."""
    lf = v.cog_from_front_axle_m
    rows = np.zeros((2, HALF_DOF))
    for i, x in enumerate(v.sensor_x_m):
        rows[i, 2] = 1.0
        rows[i, 3] = lf - x
    if v.pitch_gyro:
        rows[1] = 0.0
        rows[1, HALF_PITCH] = -1.0
    return rows


def half_car_sensor_rates(v: Vehicle) -> np.ndarray:
    """(2,) bool: the channel reads its row's rate (a gyro), not its acceleration."""
    return np.array([False, v.pitch_gyro])


def half_car_suspension_rows(v: Vehicle) -> np.ndarray:
    """(2, 4) map ``G`` from ``q`` to the corners' extensions ``e = x_s,axle - x_t`` (eqs 3-8,
    3-9): the suspension part of eq 3-5 is ``G^T diag(k_s) G``, of eq 3-6 ``G^T diag(c_s) G``."""
    lf, lr = v.cog_from_front_axle_m, v.cog_from_rear_axle_m
    return np.array([[-1.0, 0.0, 1.0, lf], [0.0, -1.0, 1.0, -lr]])


def full_car_suspension_rows(v: FullVehicle) -> np.ndarray:
    """(4, 7) map ``G`` from ``q`` to the corners' extensions ``e = z(corner) - x_t`` (FL, FR, RL, RR)."""
    g = np.zeros((FULL_CORNERS, FULL_DOF))
    g[:, :FULL_CORNERS] = -np.eye(FULL_CORNERS)
    g[:, FULL_HEAVE:] = full_car_body_rows(v, np.column_stack([v.corner_x_m, v.corner_y_m]))[:, FULL_HEAVE:]
    return g


def full_car_body_rows(v: FullVehicle, points_m: np.ndarray) -> np.ndarray:
    """(k, 7) map from ``q`` to the body's vertical motion at points ``(x, y)`` (k, 2) [m]:
    ``x_s + (lf - x) phi + (y - y_cog) theta``."""
    p = np.atleast_2d(np.asarray(points_m, dtype=float))
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points_m must have shape (k, 2) of (x, y), got {np.shape(points_m)}")
    rows = np.zeros((p.shape[0], FULL_DOF))
    rows[:, FULL_HEAVE] = 1.0
    rows[:, FULL_PITCH] = v.cog_from_front_axle_m - p[:, 0]
    rows[:, FULL_ROLL] = p[:, 1] - v.cog_lateral_m
    return rows


def full_car_sensor_points(v: FullVehicle) -> np.ndarray:
    """(4, 2) the accelerometers' ``(x, y)`` (FL, FR, RL, RR) [m]."""
    return np.column_stack([v.sensor_x_m, v.sensor_y_m])


GYRO_ROWS = {"gyro_x": (0.0, 0.0, 1.0), "gyro_y": (0.0, -1.0, 0.0)}
"""A gyro's row on the body's ``(z₀, φ, θ)`` rates (:func:`full_car_channel_rows`): ``gyro_x``
(REP 103: left side up) ``θ'``, ``gyro_y`` (nose down; ``φ`` is nose up) ``-φ'``."""


def full_car_channel_rows(vehicle: FullVehicle, sensors: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """((k, 3) each channel's row on the body's ``(z₀, φ, θ)`` (``z₀`` at the front axle's centre:
    :mod:`rozyn_estimator.method.full.spectrum`), (k,) bool: the channel reads the rate, a gyro).
    An accelerometer at ``(x, y)`` reads ``(1, -x, y)``, a gyro its :data:`GYRO_ROWS` row."""
    kinds = [vehicle.channel_kinds[c] for c in sensors]
    xs, ys = np.asarray(vehicle.sensor_x_m)[list(sensors)], np.asarray(vehicle.sensor_y_m)[list(sensors)]
    rows = np.array([GYRO_ROWS.get(kind, (1.0, -x, y)) for kind, x, y in zip(kinds, xs, ys, strict=True)])
    return rows.reshape(len(kinds), 3), np.array([kind in GYRO_ROWS for kind in kinds])


def full_car_sensor_rows(v: FullVehicle) -> np.ndarray:
    """(k, 7) map from ``q`` to what the channels read (:func:`full_car_channel_rows` in ``q``'s
    coordinates: ``z₀ = x_s + lf phi - y_cog theta``); a gyro reads its row's rate
    (:func:`full_car_sensor_rates`)."""
    body, _ = full_car_channel_rows(v, range(len(v.channel_kinds)))
    rows = np.zeros((body.shape[0], FULL_DOF))
    rows[:, FULL_HEAVE] = body[:, 0]
    rows[:, FULL_PITCH] = v.cog_from_front_axle_m * body[:, 0] + body[:, 1]
    rows[:, FULL_ROLL] = body[:, 2] - v.cog_lateral_m * body[:, 0]
    return rows


def full_car_sensor_rates(v: FullVehicle) -> np.ndarray:
    """(k,) bool: the channel reads its row's rate (a gyro), not its acceleration."""
    return full_car_channel_rows(v, range(len(v.channel_kinds)))[1]


def full_car_model(v: FullVehicle) -> SecondOrderModel:
    """Mass, damping and stiffness matrices (see the module's docstring), tyres as inputs."""
    g = full_car_suspension_rows(v)
    bars = np.zeros((FULL_CORNERS, FULL_CORNERS))  # the bars' springs between the corners' extensions
    for rows, bar_nmprad, track in ((slice(0, 2), v.anti_roll_stiffness_front_nmprad, v.track_front_m),
                                    (slice(2, 4), v.anti_roll_stiffness_rear_nmprad, v.track_rear_m)):
        bars[rows, rows] = bar_nmprad / track**2 * np.array([[1.0, -1.0], [-1.0, 1.0]])

    def corners(suspension: tuple[float, ...], tyre: tuple[float, ...], extra: np.ndarray) -> np.ndarray:
        out = g.T @ (np.diag(suspension) + extra) @ g
        out[:FULL_CORNERS, :FULL_CORNERS] += np.diag(tyre)
        return out

    stiffness = corners(v.suspension_stiffness_npm, v.tyre_stiffness_npm, bars)
    damping = corners(v.suspension_damping_nspm, v.tyre_damping_nspm, np.zeros((FULL_CORNERS, FULL_CORNERS)))
    mass = np.diag([*v.unsprung_mass_kg, v.sprung_mass_kg, v.pitch_inertia_kgm2, v.roll_inertia_kgm2])
    h = gravity_height_m(v)  # the weight through the geometry, in pitch and in roll alike
    for k in (FULL_PITCH, FULL_ROLL):
        stiffness[k, k] += rotation_stiffness_nmprad(v.sprung_mass_kg, h)
        mass[k, k] += rotation_inertia_kgm2(v.sprung_mass_kg, h, sum(v.unsprung_mass_kg))[0]
    tyre_k = np.zeros((FULL_DOF, FULL_CORNERS))
    tyre_k[:FULL_CORNERS] = np.diag(v.tyre_stiffness_npm)
    tyre_c = np.zeros((FULL_DOF, FULL_CORNERS))
    tyre_c[:FULL_CORNERS] = np.diag(v.tyre_damping_nspm)
    return SecondOrderModel(mass, damping, stiffness, tyre_k, tyre_c)


