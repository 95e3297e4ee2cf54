"""An independent check of the plants' gravity through the geometry: a planar multibody model
of a body on wheels, integrated in its nonlinear form (scipy's DOP853).

The body (mass ``m``, inertia ``I`` about its centre of gravity) moves freely in the plane:
``q = [X, Z, φ, e_1 .. e_n]``, ``(X, Z)`` its centre of gravity, ``φ`` its rotation (a point
ahead, ``ξ > 0``, rises when ``φ > 0``). Wheel ``i`` (a point mass) rides on an axis fixed in
the body at ``ξ_i``, its centre at ``(ξ_i, -h - e_i)`` in the body's frame: ``h`` below the
centre of gravity at rest, ``e_i`` the suspension's extension. Its spring and damper act along
that axis; its tyre is a vertical spring and damper between the wheel's centre and the road.
Gravity acts on everything; the springs' preloads hold the car at rest at ``q = 0``. Nothing
here is linearised or shares code with the plants: the equations are Lagrange's, with the
exact rotation, the wheels' horizontal motion and the centripetal terms.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

G = 9.80665


@dataclass(frozen=True)
class PlanarCar:
    mass_kg: float
    inertia_kgm2: float
    height_m: float  # centre of gravity above the wheel centres
    xi_m: np.ndarray  # (n,) the wheels' axes, forward (or left) of the centre of gravity
    unsprung_kg: np.ndarray
    spring_npm: np.ndarray
    damper_nspm: np.ndarray
    tyre_npm: np.ndarray
    tyre_nspm: np.ndarray
    static_load_n: np.ndarray  # (n,) each suspension's share of the body's weight


def _rotation(phi: float) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[c, -s], [s, c]]), np.array([[-s, -c], [c, -s]])  # R and dR/dφ


def simulate(car: PlanarCar, road: Callable[[float], tuple[np.ndarray, np.ndarray]], t_s: np.ndarray,
             points_xi_m: np.ndarray) -> np.ndarray:
    """Vertical accelerations (len(t_s), len(points)) of body points at ``points_xi_m`` (at the
    centre of gravity's height) driven by ``road(t) -> (heights, rates)`` under each wheel."""
    n = car.xi_m.size
    eps = car.static_load_n / car.spring_npm  # the springs' preloads
    _, _, p_rest = _wheels(car, np.zeros(3 + n))
    rho = p_rest[:, 1] + (car.static_load_n + car.unsprung_kg * G) / car.tyre_npm

    def accel(t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        jac, centripetal, p = _wheels(car, q, v)
        M = np.zeros((3 + n, 3 + n))
        M[0, 0] = M[1, 1] = car.mass_kg
        M[2, 2] = car.inertia_kgm2
        force = np.zeros(3 + n)
        force[1] -= car.mass_kg * G
        r, r_dot = road(t)
        pz_dot = jac[:, 1, :] @ v
        tyre = -car.tyre_npm * (p[:, 1] - r - rho) - car.tyre_nspm * (pz_dot - r_dot)  # up, on the wheel
        for i in range(n):
            M += car.unsprung_kg[i] * jac[i].T @ jac[i]
            force += jac[i, 1] * (tyre[i] - car.unsprung_kg[i] * G)
            force -= car.unsprung_kg[i] * jac[i].T @ centripetal[i]
        force[3:] -= car.spring_npm * (q[3:] - eps) + car.damper_nspm * v[3:]
        return np.linalg.solve(M, force)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        q, v = y[: 3 + n], y[3 + n:]
        return np.concatenate([v, accel(t, q, v)])

    sol = solve_ivp(rhs, (t_s[0], t_s[-1]), np.zeros(2 * (3 + n)), method="DOP853", t_eval=t_s,
                    rtol=1e-10, atol=1e-12)
    assert sol.success, sol.message
    out = np.zeros((t_s.size, points_xi_m.size))
    for k, t in enumerate(t_s):
        q, v = sol.y[: 3 + n, k], sol.y[3 + n:, k]
        a = accel(t, q, v)
        R, dR = _rotation(q[2])
        for j, xi in enumerate(points_xi_m):
            b = np.array([xi, 0.0])
            out[k, j] = a[1] + (dR @ b)[1] * a[2] - (R @ b)[1] * v[2] ** 2  # R'' = -R
    return out


def _wheels(car: PlanarCar, q: np.ndarray, v: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(the wheels' Jacobians (n, 2, 3 + n), their accelerations at zero q̈ (n, 2), their centres (n, 2))."""
    n = car.xi_m.size
    R, dR = _rotation(q[2])
    jac = np.zeros((n, 2, 3 + n))
    centripetal = np.zeros((n, 2))
    centres = np.zeros((n, 2))
    down = np.array([0.0, -1.0])
    for i in range(n):
        b = np.array([car.xi_m[i], -car.height_m - q[3 + i]])
        centres[i] = q[:2] + R @ b
        jac[i, :, :2] = np.eye(2)
        jac[i, :, 2] = dR @ b
        jac[i, :, 3 + i] = R @ down
        if v is not None:
            centripetal[i] = -(R @ b) * v[2] ** 2 + 2.0 * (dR @ down) * v[2] * v[3 + i]
    return jac, centripetal, centres
