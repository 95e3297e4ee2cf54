"""The body's inertial parameters as the likelihood fits them, for any vehicle: the half car's
``(m, I_yy, l_f)`` (the body heaves and pitches) and the full car's ``(m, I_xx, I_yy, l_f,
y_c)`` (it also rolls), each through an unconstrained θ: ``ln m``, the inertias' logs,
``logit(l_f / L)`` (the CoG between the axles) and ``y_c`` itself.

The body's coordinates are taken at the front axle's centre, ``q = (z₀, φ[, θ])``: a point
``(x, y)`` moves ``z₀ - x φ + y θ`` and the centre of gravity ``t·q`` with ``t = (1, -l_f[,
y_c])``, so the mass matrix is ``M = m t tᵀ + diag(0, I_yy[, I_xx])`` (the inertias enter
only there), with the wheels' swing ``μ h²`` on each rotation and the weight's ``-m g h``
on its stiffness where the vehicle gives its heights (:mod:`rozyn_estimator.gravity`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from rozyn_estimator.gravity import rotation_inertia_kgm2, rotation_stiffness_nmprad

FULL_BODY_NAMES = ("ln_mass", "ln_roll_inertia", "ln_pitch_inertia", "logit_cog", "cog_lateral_m")
HALF_BODY_NAMES = ("ln_mass", "ln_pitch_inertia", "logit_cog")


@dataclass(frozen=True)
class BodyParameters:
    """The map between θ's body block and the physical parameters, and the mass matrix."""

    wheelbase_m: float  # l_f's scale in θ
    rolls: bool  # the full car: θ also holds I_xx and y_c
    gravity_height_m: float = 0.0  # the CoG above the wheel centres (0: the geometry not carried)
    unsprung_total_kg: float = 0.0  # the wheels' masses together (their swing)

    @property
    def names(self) -> tuple[str, ...]:
        return FULL_BODY_NAMES if self.rolls else HALF_BODY_NAMES

    @property
    def size(self) -> int:
        """How many body parameters θ holds (3 or 5), also the body's physical ones."""
        return len(self.names)

    @property
    def coordinates(self) -> int:
        """The body's coordinates ``q``: heave and pitch, and roll where it rolls."""
        return 3 if self.rolls else 2

    def theta(self, params: np.ndarray) -> np.ndarray:
        """θ's body block from the physical parameters (the full car's order: m, I_xx, I_yy,
        l_f, y_c; the half car's: m, I_yy, l_f): the mass and inertias by their logs, l_f by its
        share's logit, y_c as it is."""
        out = np.array(params, dtype=float)
        j = self.lf_index
        out[:j] = np.log(out[:j])
        out[j] = special.logit(out[j] / self.wheelbase_m)
        return out

    def physical(self, theta: np.ndarray) -> np.ndarray:
        """The physical parameters [kg, kg m², m] from θ's body block."""
        out = np.array(theta[: self.size], dtype=float)
        j = self.lf_index
        with np.errstate(over="ignore"):
            out[:j] = np.exp(out[:j])
        out[j] = special.expit(out[j]) * self.wheelbase_m
        return out

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """(size, size) d(physical)/dθ: diagonal."""
        values = self.physical(theta)
        p = values[self.lf_index] / self.wheelbase_m
        diag = np.ones(self.size)
        diag[: self.lf_index] = values[: self.lf_index]
        diag[self.lf_index] = self.wheelbase_m * p * (1 - p)
        return np.diag(diag)

    @property
    def lf_index(self) -> int:
        return 3 if self.rolls else 2

    def mass_matrix(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """M (b, b) and dM/dθ (size, b, b) in ``q = (z₀, φ[, θ])``."""
        values = self.physical(theta)
        m, lf = values[0], values[self.lf_index]
        iyy = values[2] if self.rolls else values[1]
        t = np.array([1.0, -lf, values[4]]) if self.rolls else np.array([1.0, -lf])
        tt = np.outer(t, t)
        swing, d_swing = rotation_inertia_kgm2(m, self.gravity_height_m, self.unsprung_total_kg)
        rotations = np.diag([0.0, 1.0, 1.0][: t.size])
        inertias = np.array([0.0, iyy, values[1]])[: t.size] if self.rolls else np.array([0.0, iyy])
        M = m * tt + np.diag(inertias) + swing * rotations
        e_pitch = np.zeros(t.size)
        e_pitch[1] = -1.0
        d_lf = np.outer(e_pitch, t)
        p = lf / self.wheelbase_m
        d_logit = m * (d_lf + d_lf.T) * self.wheelbase_m * p * (1 - p)
        d_mass = m * tt + d_swing * rotations
        d_pitch = np.diag(np.array([0.0, iyy, 0.0])[: t.size])
        if not self.rolls:
            return M, np.array([d_mass, d_pitch, d_logit])
        d_yc = np.outer([0.0, 0.0, 1.0], t)
        d_roll = np.diag([0.0, 0.0, values[1]])
        return M, np.array([d_mass, d_roll, d_pitch, d_logit, m * (d_yc + d_yc.T)])

    def swing_slope(self, theta: np.ndarray) -> float:
        """d(μ h²)/d(the unsprung masses together): how a wheel's mass moves the rotations' inertia."""
        m = math.exp(theta[0])
        return (m / (m + self.unsprung_total_kg)) ** 2 * self.gravity_height_m**2

    def gravity_stiffness(self, theta: np.ndarray) -> np.ndarray:
        """The weight's stiffness ``-m g h`` on the rotations (b, b), also its ln m derivative."""
        k = rotation_stiffness_nmprad(math.exp(theta[0]), self.gravity_height_m)
        return np.diag([0.0, k, k][: self.coordinates])
