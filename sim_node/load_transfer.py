"""Accelerating and braking pitch the body: the load transfer ``m h a_x`` in the simulator.

A vehicle accelerating at ``a_x`` [m/s²] is pushed by its tyres at the road, ``h`` below its
centre of gravity (``cog_height_m``): a pitch moment ``m h a_x`` on the sprung body (nose up
when accelerating, down when braking), carried by the suspension's springs and dampers. The
suspension has no anti-dive or anti-squat geometry, so all of it reaches the body; the
unsprung masses' own share goes through their tyres and is left out.

The vehicle is linear, so its response to this moment adds to the road's: a second plant of
the same vehicle (the same modes, sensors and sensor delays, no road) driven by ``a_x`` alone
(:class:`sim_node.plant.SuspendedPlant`, whose input is then the acceleration, piecewise linear
between steps like the road), plus the moment's direct acceleration of the body (undelayed: a
sensor's delay of milliseconds on a driver's acceleration is negligible). With a nonlinear
suspension (a departure) the sum is the linearised response to the moment, a second-order
approximation. Where the vehicle gives no heights, or at a constant speed, there is nothing to add.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim_node.modal import SecondOrderModel, static_state_of
from sim_node.plant import SuspendedPlant


def pitch_moment_model(model: SecondOrderModel, pitch: int, mass_kg: float,
                       cog_height_m: float) -> SecondOrderModel:
    """``model`` with the longitudinal acceleration [m/s²] as its one input: the generalised force
    ``m h a_x`` on coordinate ``pitch`` (positive nose up), nothing through the tyres."""
    force = np.zeros((model.dof, 1))
    force[pitch, 0] = mass_kg * cog_height_m
    return SecondOrderModel(model.mass, model.damping, model.stiffness, force, np.zeros_like(force))


class LoadTransfer:
    """The body's acceleration at the sensors from the load transfer, block by block.

    Args:
        model: the vehicle's second-order model (the road's inputs are replaced).
        body_rows: (sensors, dof) rows reading the body's acceleration at the sensors.
        corners: (corners, dof) the suspension's extension rows.
        pitch: the index of the body's pitch in ``q``.
        mass_kg: sprung mass.
        cog_height_m: the CoG's height above the road.
        dt_s: the plant's step [s].
        accel0_mps2: the acceleration at the first step: the body starts at rest under it.
        delays_s: each sensor's delay (as the road's plant).
        rates: (sensors,) bool: these read their row's rate (a gyro), with no direct term.
    """

    def __init__(self, model: SecondOrderModel, body_rows: np.ndarray, corners: np.ndarray, pitch: int,
                 mass_kg: float, cog_height_m: float, dt_s: float, accel0_mps2: float,
                 delays_s: Sequence[float] = (), rates: np.ndarray | None = None) -> None:
        driven = pitch_moment_model(model, pitch, mass_kg, cog_height_m)
        # the plant's outputs read the body's states only (a road acts through the wheels); a
        # moment on the body also accelerates it directly, at once: M⁻¹ f a_x at the sensors
        self._direct = body_rows @ np.linalg.solve(driven.mass, driven.tyre_stiffness[:, 0])
        if rates is not None:
            self._direct[rates] = 0.0
        u0 = np.array([accel0_mps2])
        self._plant = SuspendedPlant(driven, body_rows, corners, dt_s, x0=static_state_of(driven, u0), u0=u0,
                                     delays_s=delays_s, what="load transfer", rates=rates)

    def run(self, accel_mps2: np.ndarray) -> np.ndarray:
        """(n, sensors) body acceleration from the load transfer at steps of longitudinal
        acceleration ``accel_mps2`` (n,) [m/s²]."""
        a = np.asarray(accel_mps2, dtype=float)
        return self._plant.run(a[:, None]) + a[:, None] * self._direct


__all__ = ["LoadTransfer", "pitch_moment_model"]
