"""The vehicle's equations of motion ``M q'' + C q' + K q = Kt u + Ct u'``: one rigid body on a
list of corners, each a suspension (spring, damper) above a wheel above a tyre, with anti-roll
bars between corners, and the weight through the geometry where the vehicle gives its heights
(:mod:`rozyn_estimator.gravity`).

The half car (thesis chapter 3, eqs 3-4 to 3-9, typos corrected) is its two-corner case on the
centreline: the body heaves and pitches. The full car is its four-corner case: the body heaves,
pitches and rolls. ``q`` holds the wheels' heave (the vehicle's corner order: front, rear; or FL,
FR, RL, RR), then the body's heave at its centre of gravity, its pitch (positive nose up) and,
where it rolls, its roll (positive left side up). A body point at ``(x, y)`` (behind the front
axle, left of the centreline) moves ``x_s + (lf - x) phi + (y - y_cog) theta`` (eqs 3-8, 3-9
widened). With ``G`` the map from ``q`` to the corners' extensions ``e = z(corner) - x_t``::

    M = diag(m_t, m_s, I_yy[, I_xx])                               (eq 3-4)
    K = diag(k_t, 0…) + G^T (diag(k_s) + B) G                      (eq 3-5)
    C = diag(c_t, 0…) + G^T diag(c_s) G                            (eq 3-6)

with ``B`` the bars' springs between their corners' extensions (a bar of roll stiffness ``K``
[N m/rad] across a track ``t`` is ``K / t²`` N/m).

The simulator's plant (:mod:`sim_node.plant`) runs these matrices, and the estimator uses them
for what it must predict in the time domain (the body's response to the load transfer of
accelerating and braking, :mod:`rozyn_estimator.method.load_transfer`), so the plant and the
observer share the vehicle as they share its parameters.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.corners import Corners
from rozyn_estimator.gravity import gravity_height_m, rotation_inertia_kgm2, rotation_stiffness_nmprad
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle

AnyVehicle = Vehicle | FullVehicle

GYRO_ROWS = {"gyro_x": (0.0, 0.0, 1.0), "gyro_y": (0.0, -1.0, 0.0)}
"""A gyro's row on the body's ``(z₀, φ, θ)`` rates (:func:`channel_rows`): ``gyro_x`` (REP 103:
left side up) ``θ'``, ``gyro_y`` (nose down; ``φ`` is nose up) ``-φ'``."""


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


def body_inertias(v: AnyVehicle) -> np.ndarray:
    """The body's (m, I_yy[, I_xx]) [kg, kg m²], in ``q``'s order (its heave, pitch, roll)."""
    b = v.body_values  # m, [I_xx,] I_yy, l_f[, y_c]: the likelihood's order
    return np.array([b[0], b[2], b[1]]) if v.ROLLS else b[:2]


def corner_count(v: AnyVehicle) -> int:
    """How many corners (wheels, tyres) the vehicle stands on."""
    return v.CORNER_COUNT


def heave_index(v: AnyVehicle) -> int:
    """The body's heave in ``q``; its pitch follows, then its roll (where it rolls)."""
    return corner_count(v)


def pitch_index(v: AnyVehicle) -> int:
    """The body's pitch (positive nose up) in ``q``."""
    return heave_index(v) + 1


def dof(v: AnyVehicle) -> int:
    """The length of ``q``: the wheels and the body's two or three coordinates."""
    return corner_count(v) + len(body_inertias(v))


def body_rows(v: AnyVehicle, points_m: np.ndarray) -> np.ndarray:
    """(k, dof) map from ``q`` to the body's vertical motion at points ``(x, y)`` (k, 2) [m]:
    ``x_s + (lf - x) phi + (y - y_cog) theta`` (a body that does not roll: ``y`` must be 0)."""
    p = np.atleast_2d(np.asarray(points_m, dtype=float))
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points_m must have shape (k, 2) of (x, y), got {np.shape(points_m)}")
    if not v.ROLLS and np.any(p[:, 1] != 0.0):
        raise ValueError("a body that does not roll (the half car) has its points on the centreline: y = 0")
    rows = np.zeros((p.shape[0], dof(v)))
    heave = heave_index(v)
    rows[:, heave] = 1.0
    rows[:, heave + 1] = v.cog_from_front_axle_m - p[:, 0]
    if v.ROLLS:
        rows[:, heave + 2] = p[:, 1] - v.cog_lateral_m
    return rows


def suspension_rows(v: AnyVehicle) -> np.ndarray:
    """(corners, dof) map ``G`` from ``q`` to the corners' extensions ``e = z(corner) - x_t``
    (eqs 3-8, 3-9): the suspension part of eq 3-5 is ``G^T diag(k_s) G``, of eq 3-6 ``G^T diag(c_s) G``."""
    c = v.corners
    g = body_rows(v, np.column_stack([c.x_m, c.y_m]))
    g[:, : c.count] = -np.eye(c.count)
    return g


def second_order_model(v: AnyVehicle) -> SecondOrderModel:
    """Mass, damping and stiffness matrices (eqs 3-4 to 3-7 on the vehicle's corners; see the
    module's docstring), the road under each tyre as the inputs."""
    c = v.corners
    g = suspension_rows(v)

    def on_corners(suspension: np.ndarray, tyre: np.ndarray, between: np.ndarray) -> np.ndarray:
        # the same pattern for stiffness (eq 3-5) and damping (eq 3-6): suspension elements between
        # wheel and body point, tyre elements between road and wheel
        out = g.T @ (np.diag(suspension) + between) @ g
        out[: c.count, : c.count] += np.diag(tyre)
        return out

    stiffness = on_corners(c.suspension_stiffness_npm, c.tyre_stiffness_npm, c.bars_npm)
    damping = on_corners(c.suspension_damping_nspm, c.tyre_damping_nspm, np.zeros_like(c.bars_npm))
    mass = np.diag(np.concatenate([c.unsprung_mass_kg, body_inertias(v)]))
    h = gravity_height_m(v)  # the weight through the geometry (0 where the heights are not given)
    for k in range(heave_index(v) + 1, dof(v)):  # pitch and roll alike
        stiffness[k, k] += rotation_stiffness_nmprad(v.sprung_mass_kg, h)
        mass[k, k] += rotation_inertia_kgm2(v.sprung_mass_kg, h, float(c.unsprung_mass_kg.sum()))[0]
    tyre_k = np.zeros((dof(v), c.count))
    tyre_k[: c.count] = np.diag(c.tyre_stiffness_npm)
    tyre_c = np.zeros((dof(v), c.count))
    tyre_c[: c.count] = np.diag(c.tyre_damping_nspm)
    return SecondOrderModel(mass, damping, stiffness, tyre_k, tyre_c)


def channel_rows(v: AnyVehicle, sensors: Sequence[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((k, b) each channel's row on the body's ``(z₀, φ[, θ])`` (``z₀`` at the front axle's
    centre: :mod:`rozyn_estimator.method.vehicle_fit.spectrum`), (k,) bool: the channel reads the rate,
    a gyro) for the channels ``sensors`` (default all). An accelerometer at ``(x, y)`` reads
    ``(1, -x, y)``, a gyro its :data:`GYRO_ROWS` row."""
    index = list(range(len(v.channel_kinds)) if sensors is None else sensors)
    kinds = [v.channel_kinds[c] for c in index]
    xs, ys = np.asarray(v.sensor_x_m)[index], np.asarray(v.sensor_y_m)[index]
    rows = np.array([GYRO_ROWS.get(kind, (1.0, -x, y)) for kind, x, y in zip(kinds, xs, ys, strict=True)])
    b = 3 if v.ROLLS else 2
    return rows.reshape(len(kinds), 3)[:, :b], np.array([kind in GYRO_ROWS for kind in kinds])


def sensor_rows(v: AnyVehicle) -> np.ndarray:
    """(k, dof) map from ``q`` to what the channels read (:func:`channel_rows` in ``q``'s
    coordinates: ``z₀ = x_s + lf phi - y_cog theta``); a gyro reads its row's rate
    (:func:`sensor_rates`), an accelerometer the acceleration."""
    body, _ = channel_rows(v)
    rows = np.zeros((body.shape[0], dof(v)))
    heave = heave_index(v)
    rows[:, heave] = body[:, 0]
    rows[:, heave + 1] = v.cog_from_front_axle_m * body[:, 0] + body[:, 1]
    if v.ROLLS:
        rows[:, heave + 2] = body[:, 2] - v.cog_lateral_m * body[:, 0]
    return rows


def sensor_rates(v: AnyVehicle) -> np.ndarray:
    """(k,) bool: the channel reads its row's rate (a gyro), not its acceleration."""
    return channel_rows(v)[1]


def sensor_points(v: AnyVehicle) -> np.ndarray:
    """(k, 2) the channels' ``(x, y)`` [m] (a gyro's position is where its sensor sits)."""
    return np.column_stack([v.sensor_x_m, v.sensor_y_m])


__all__ = ["GYRO_ROWS", "AnyVehicle", "Corners", "SecondOrderModel", "body_inertias", "body_rows",
           "channel_rows", "corner_count", "dof", "heave_index", "pitch_index",
           "second_order_model", "sensor_points", "sensor_rates", "sensor_rows", "suspension_rows"]
