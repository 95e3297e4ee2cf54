"""The 4-DOF half car (thesis chapter 3) and its exact, streaming discretisation.

Generalised coordinates (eq 3-1): ``q = [x_tf, x_tr, x_s, phi]`` — front and rear
wheel heave, body heave at the centre of gravity, body pitch (positive nose up).
Body points at the axles move ``x_sf = x_s + lf*phi`` and ``x_sr = x_s - lr*phi``
(eqs 3-8, 3-9; the thesis prints ``l_f`` in 3-9 and in the rear damping term of 3-6,
both typos corrected here).

The road enters through the tyres as displacement (tyre stiffness) and velocity (tyre
damping). The road displacement is taken piecewise linear between simulation steps
(first-order hold), so the discretisation is exact for it: the damping term's
derivative input is removed by a state shift and the result discretised with
``scipy.signal.cont2discrete(method="foh")``. Blocks are propagated in modal
coordinates with one first-order ``lfilter`` per mode, so there is no Python loop per
sample, and the state carries over so a long run equals the concatenation of blocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, solve
from scipy.signal import cont2discrete, lfilter

from rozyn_estimator.vehicle import Vehicle

N_DOF = 4
N_STATE = 2 * N_DOF


@dataclass(frozen=True)
class SecondOrderModel:
    """``M q'' + C q' + K q = Kt u + Ct u'`` with ``u = [road_front, road_rear]`` [m]."""

    mass: np.ndarray  # (4, 4) eq 3-4
    damping: np.ndarray  # (4, 4) eq 3-6
    stiffness: np.ndarray  # (4, 4) eq 3-5
    tyre_stiffness: np.ndarray  # (4, 2) road displacement -> generalised force
    tyre_damping: np.ndarray  # (4, 2) road velocity -> generalised force


def second_order_model(v: Vehicle) -> SecondOrderModel:
    """Mass, damping and stiffness matrices of eqs 3-4 to 3-7 (typos corrected)."""
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


@dataclass(frozen=True)
class StateSpace:
    """``xi' = a xi + b u``, ``y = c xi + d u`` with ``xi = x - shift @ u``.

    ``x = [q, q']`` (eq 3-2); ``y`` the body accelerations at the sensors [m/s^2]. The
    shift removes the road-velocity input so ``u`` is the road displacement only.
    """

    a: np.ndarray  # (8, 8) eq 3-11
    b: np.ndarray  # (8, 2)
    c: np.ndarray  # (2, 8)
    d: np.ndarray  # (2, 2)
    shift: np.ndarray  # (8, 2)


def state_space(v: Vehicle) -> StateSpace:
    """Continuous state space of the half car with road displacement as input."""
    m = second_order_model(v)
    minv_k = solve(m.mass, m.stiffness, assume_a="diagonal")
    minv_c = solve(m.mass, m.damping, assume_a="diagonal")
    a = np.block([[np.zeros((N_DOF, N_DOF)), np.eye(N_DOF)], [-minv_k, -minv_c]])  # eq 3-11
    b0 = np.vstack([np.zeros((N_DOF, 2)), solve(m.mass, m.tyre_stiffness, assume_a="diagonal")])
    b1 = np.vstack([np.zeros((N_DOF, 2)), solve(m.mass, m.tyre_damping, assume_a="diagonal")])
    c = sensor_rows(v) @ a[N_DOF:, :]  # body rows carry no direct road input
    return StateSpace(a=a, b=a @ b1 + b0, c=c, d=c @ b1, shift=b1)


def static_state(v: Vehicle, road_m: np.ndarray) -> np.ndarray:
    """State ``x`` at rest on a road held at ``road_m = [front, rear]`` [m]."""
    m = second_order_model(v)
    q = solve(m.stiffness, m.tyre_stiffness @ np.asarray(road_m, dtype=float))
    return np.concatenate([q, np.zeros(N_DOF)])


class HalfCarPlant:
    """Exact-discretised half car, propagated block by block.

    Args:
        vehicle: the vehicle.
        dt_s: simulation step [s]; the road is piecewise linear between steps.
        x0: initial physical state ``[q, q']`` (default: at rest, zero road).
        u0: road displacement at the first step, for the state shift [m].
    """

    def __init__(
        self,
        vehicle: Vehicle,
        dt_s: float,
        x0: np.ndarray | None = None,
        u0: np.ndarray | None = None,
    ) -> None:
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
        self.vehicle = vehicle
        self.dt_s = float(dt_s)
        ss = state_space(vehicle)
        ad, bd, cd, dd, _ = cont2discrete((ss.a, ss.b, ss.c, ss.d), self.dt_s, method="foh")
        # scipy's FOH state is xi - g @ u; recover g to map physical states in and out.
        self._foh_shift = ss.shift + _foh_input_shift(ss.a, ss.b, self.dt_s)
        eigvals, modes = np.linalg.eig(ad)
        if np.linalg.cond(modes) > 1e10:
            raise ValueError("half-car transition matrix is not diagonalisable (repeated poles)")
        to_modal = np.linalg.inv(modes)
        # The state is real, so conjugate modes carry conjugate coordinates: propagate
        # one of each pair and count it twice in the output.
        keep = eigvals.imag >= 0.0
        self._lam = eigvals[keep]
        self._to_modal = to_modal[keep]
        self._in_modal = self._to_modal @ bd
        self._out_modal = (cd @ modes)[:, keep] * np.where(eigvals[keep].imag > 0.0, 2.0, 1.0)
        self._dd = dd
        x0 = np.zeros(N_STATE) if x0 is None else np.asarray(x0, dtype=float)
        u0 = np.zeros(2) if u0 is None else np.asarray(u0, dtype=float)
        self._z = self._to_modal @ (x0 - self._foh_shift @ u0)

    @property
    def state(self) -> np.ndarray:
        """Internal (shifted, modal) state; opaque, but enough to continue a run."""
        return self._z.copy()

    def run(self, road_m: np.ndarray) -> np.ndarray:
        """Advance over a block of road displacements.

        Args:
            road_m: (n, 2) front/rear road displacement at steps k, k+1, … [m]; the
                first row is the road at the current state's time.

        Returns:
            (n, 2) body vertical acceleration at the front/rear sensors at those
            steps [m/s^2], gravity excluded.
        """
        u = np.asarray(road_m, dtype=float)
        if u.ndim != 2 or u.shape[1] != 2:
            raise ValueError(f"road_m must have shape (n, 2), got {u.shape}")
        n = u.shape[0]
        if n == 0:
            return np.zeros((0, 2))
        drive = (u @ self._in_modal.T).T  # (modes, n)
        z = np.empty((self._lam.size, n + 1), dtype=complex)
        z[:, 0] = self._z
        for j, lam in enumerate(self._lam):
            # z[k+1] = lam z[k] + drive[k], one C loop per mode
            z[j, 1:] = lfilter([1.0], [1.0, -lam], drive[j], zi=[lam * self._z[j]])[0]
        self._z = z[:, n]
        return (self._out_modal @ z[:, :n]).real.T + u @ self._dd.T


def _foh_input_shift(a: np.ndarray, b: np.ndarray, dt_s: float) -> np.ndarray:
    """The ``g`` of scipy's FOH discretisation (its state is ``xi - g u``)."""
    n, m = b.shape
    em = np.zeros((n + 2 * m, n + 2 * m))
    em[:n, :n] = a * dt_s
    em[:n, n : n + m] = b * dt_s
    em[n : n + m, n + m :] = np.eye(m)
    return expm(em)[:n, n + m :]


def free_decay(vehicle: Vehicle, x0: np.ndarray, dt_s: float, n: int) -> np.ndarray:
    """Sensor accelerations of the free decay from state ``x0`` on a flat road."""
    return HalfCarPlant(vehicle, dt_s, x0=x0).run(np.zeros((n, 2)))


def natural_modes(v: Vehicle) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], damping ratio) of the four modes, sorted by frequency."""
    lam = np.linalg.eigvals(state_space(v).a)
    lam = lam[lam.imag > 0]
    wn = np.abs(lam)
    order = np.argsort(wn)
    return wn[order] / (2 * np.pi), (-lam.real / wn)[order]
