"""The 4-DOF half car (thesis chapter 3) and its exact, streaming discretisation.

Generalised coordinates (eq 3-1): ``q = [x_tf, x_tr, x_s, phi]`` — front and rear
wheel heave, body heave at the centre of gravity, body pitch (positive nose up).
Body points at the axles move ``x_sf = x_s + lf*phi`` and ``x_sr = x_s - lr*phi``
(eqs 3-8, 3-9; the thesis prints ``l_f`` in 3-9 and in the rear damping term of 3-6,
both typos corrected here).

The road enters through the tyres as displacement and velocity; the model is discretised
exactly (first-order hold) and propagated block by block in modal coordinates by
:mod:`sim_node.modal`, so a long run equals the concatenation of blocks.

Departures from the linear model (:mod:`sim_node.departures`), both off by default:

- A nonlinear suspension: each corner's tension is the linear ``k e + c v`` of eqs 3-5,
  3-6 plus an extra ``f(e, v)``, two more inputs of the same exact discretisation,
  piecewise linear between steps like the road. A block's ``f`` is the fixed point of
  "run the linear half car on the road and ``f`` (vectorised), read ``e, v`` off its
  states, evaluate ``f``" (:mod:`sim_node.fixed_point`), to ``TENSION_RTOL``. For the
  asymmetric dampers (slope ``a c``, ``a = (ratio - 1)/(ratio + 1)``, on a port whose
  admittance the damper ``c`` bounds by ``1/c``) it contracts by ``|a|`` per iteration;
  for the springs while ``3 p (e/e_ref)^2`` is moderate. The fixed point is unique, so
  blocks cut anywhere give the same run; what is left is the first-order hold of ``f``,
  second order in the step (``test_halfcar``: against an ODE solver).
- Delayed sensors (``delays_s``): the output a fraction of a step after an earlier step,
  exact too (the augmented exponential over that fraction), from the states and inputs of
  the last steps, kept across blocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve

from rozyn_estimator.vehicle import Vehicle
from sim_node.departures import SuspensionLaw
from sim_node.fixed_point import solve_fixed_point
from sim_node.modal import (
    ModalPropagator,
    SecondOrderModel,
    StateSpace,
    foh_input_shift,
    natural_modes_of,
    ramp_response,
    state_space_of,
    static_state_of,
)

N_DOF = 4
N_STATE = 2 * N_DOF
TENSION_RTOL = 1e-12  # the fixed point's tolerance, share of the largest extra tension
TENSION_ATOL_N = 1e-9  # ... and in newtons (a block at rest)
MAX_ITERATIONS = 100  # per block
DENSE_STEPS = 256  # blocks up to this many steps solve their tensions with a response matrix
NOT_CONVERGED = ("departures: the nonlinear suspension did not converge; use a damper_ratio closer to 1, a "
                 "smaller spring_progression or a larger spring_reference_m")


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


def suspension_rows(v: Vehicle) -> np.ndarray:
    """(2, 4) map ``G`` from ``q`` to the corners' extensions ``e = x_s,axle - x_t`` (eqs 3-8,
    3-9): the suspension part of eq 3-5 is ``G^T diag(k_s) G``, of eq 3-6 ``G^T diag(c_s) G``."""
    lf, lr = v.cog_from_front_axle_m, v.cog_from_rear_axle_m
    return np.array([[-1.0, 0.0, 1.0, lf], [0.0, -1.0, 1.0, -lr]])


def state_space(v: Vehicle) -> StateSpace:
    """Continuous state space of the half car with road displacement as input."""
    return state_space_of(second_order_model(v), sensor_rows(v))


def with_tension_inputs(ss: StateSpace, v: Vehicle) -> StateSpace:
    """``ss`` with the corners' extra suspension tensions [N] as two more inputs, after the road's.

    A tension ``f`` pulls body and wheel together: generalised force ``-G^T f`` (eq 3-3's
    right-hand side), no derivative input, and a direct path to the body's accelerations.
    """
    m = second_order_model(v)
    accel = -solve(m.mass, suspension_rows(v).T, assume_a="diagonal")  # (4, 2) q'' per newton
    b = np.vstack([np.zeros((N_DOF, 2)), accel])
    return StateSpace(a=ss.a, b=np.hstack([ss.b, b]), c=ss.c, d=np.hstack([ss.d, sensor_rows(v) @ accel]),
                      shift=np.hstack([ss.shift, np.zeros((N_STATE, 2))]))


def static_state(v: Vehicle, road_m: np.ndarray) -> np.ndarray:
    """State ``x`` at rest on a road held at ``road_m = [front, rear]`` [m]."""
    return static_state_of(second_order_model(v), road_m)


class HalfCarPlant:
    """Exact-discretised half car, propagated block by block.

    Args:
        vehicle: the vehicle.
        dt_s: simulation step [s]; the road is piecewise linear between steps.
        x0: initial physical state ``[q, q']`` (default: at rest, zero road).
        u0: road displacement at the first step, for the state shift [m].
        suspension: the suspension's nonlinear part (None: the linear eqs 3-5, 3-6).
        delays_s: (front, rear) delay of each output behind its step [s], >= 0. Before the
            first step the plant is taken as having held ``x0`` (an approximation for the
            first ``delay`` of a run; the simulator's settling time covers it).
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
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
        if not all(d >= 0.0 for d in delays_s):
            raise ValueError(f"delays_s must be >= 0, got {delays_s!r}")
        self.vehicle = vehicle
        self.dt_s = float(dt_s)
        ss = state_space(vehicle)
        if suspension is not None:
            ss = with_tension_inputs(ss, vehicle)
        self._modal = p = ModalPropagator(ss, self.dt_s, "half-car")
        self._foh_shift = p.foh_shift
        self._lam = p.lam
        self._in_modal = p.in_modal
        x0 = np.zeros(N_STATE) if x0 is None else np.asarray(x0, dtype=float)
        u0 = np.zeros(2) if u0 is None else np.asarray(u0, dtype=float)
        self._law = suspension
        self._response: tuple[int, np.ndarray] | None = None
        self.iterations = 0  # linear runs the last block's fixed point took (0: a linear plant)
        if suspension is not None:
            # the corners' [e_f, e_r, v_f, v_r] from the modal state and the inputs
            motion = np.kron(np.eye(2), suspension_rows(vehicle))
            self._motion_modal = p.project(motion)
            self._motion_direct = motion @ self._foh_shift
            self._tension = suspension.extra_tension_n(*np.split(motion @ x0, 2))
            u0 = np.concatenate([u0, self._tension])
        self._z = p.modal_state(x0, u0)
        self._delayed = [_delayed_output(i, d, ss, self.dt_s, p.modes[:, p.keep] * p.weight)
                         for i, d in enumerate(delays_s) if d > 0.0]
        depth = max((d.steps + 1 for d in self._delayed), default=0)
        self._history_z = np.repeat(self._z[:, None], depth, axis=1)
        self._history_u = np.repeat(u0[None, :], depth, axis=0)

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
            steps (each less its delay) [m/s^2], gravity excluded.

        Raises:
            ConfigError: the nonlinear suspension's iteration did not converge.
        """
        u = np.asarray(road_m, dtype=float)
        if u.ndim != 2 or u.shape[1] != 2:
            raise ValueError(f"road_m must have shape (n, 2), got {u.shape}")
        n = u.shape[0]
        if n == 0:
            return np.zeros((0, 2))
        if self._law is None:
            inputs = u
            out, z = self._modal.run(u, self._z)
        else:
            inputs, z = self._solve_tensions(u)
            out = self._modal.output(z[:, :n], inputs)
        self._z = z[:, n]
        if self._delayed:
            out = self._delay(out, z[:, :n], inputs)
        return out

    def _solve_tensions(self, road: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The block's inputs ``[road, extra tension]`` (n, 4) at the fixed point, and its states.

        The corners' motion ``[e_f, e_r, v_f, v_r]`` is the road's response (once) plus the
        tensions' from rest: per iteration one linear run (vectorised), or for short blocks
        (the node's) one product with the block's response matrix, which skips the per-call
        overhead of the filters.
        """
        n = road.shape[0]
        law = self._law
        assert law is not None
        z_road = self._modal.propagate((road @ self._in_modal[:, :2].T).T, self._z)
        motion_road = (self._motion_modal @ z_road[:, :n]).real + self._motion_direct[:, :2] @ road.T
        drive, direct = self._in_modal[:, 2:], self._motion_direct[:, 2:]
        rest = np.zeros_like(self._z)
        response = self._tension_response(n) if n <= DENSE_STEPS else None

        def tensions(tension: np.ndarray) -> tuple[np.ndarray, None]:  # (2, n) -> (2, n)
            if response is not None:
                motion = motion_road + (response @ tension.ravel()).reshape(4, n)
            else:
                z = self._modal.propagate(drive @ tension, rest)
                motion = motion_road + (self._motion_modal @ z[:, :n]).real + direct @ tension
            return law.extra_tension_n(motion[:2].T, motion[2:].T).T, None

        guess = np.repeat(self._tension[:, None], n, axis=1)  # the last step's, held
        solved = solve_fixed_point(tensions, guess, rtol=TENSION_RTOL, atol=TENSION_ATOL_N,
                                   max_evaluations=MAX_ITERATIONS, failure=NOT_CONVERGED)
        self.iterations = solved.evaluations
        self._tension = solved.x[:, -1].copy()
        return np.hstack([road, solved.x.T]), z_road + self._modal.propagate(drive @ solved.x, rest)

    def _tension_response(self, n: int) -> np.ndarray:
        """(4n, 2n) map from a block's tensions (2, n) to the corners' motion they cause from
        rest (4, n): block lower-triangular Toeplitz in the Markov parameters (kept per ``n``)."""
        if self._response is None or self._response[0] != n:
            powers = self._lam[None, :] ** np.arange(n - 1)[:, None]  # (n - 1, modes)
            markov = np.einsum("qm,im,mr->iqr", self._motion_modal, powers, self._in_modal[:, 2:]).real
            lag = np.subtract.outer(np.arange(n), np.arange(n)) - 1  # k - j - 1; < 0: no effect yet
            blocks = np.concatenate([markov, np.zeros((1, 4, 2))])[np.where(lag >= 0, lag, n - 1)]
            blocks[np.arange(n), np.arange(n)] = self._motion_direct[:, 2:]  # same step: the FOH shift
            self._response = (n, blocks.transpose(2, 0, 3, 1).reshape(4 * n, 2 * n))
        return self._response[1]

    def _delay(self, out: np.ndarray, z: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """``out`` with its delayed channels replaced by the output ``delay`` earlier."""
        depth = self._history_u.shape[0]
        zs = np.concatenate([self._history_z, z], axis=1)
        us = np.concatenate([self._history_u, inputs])
        n = inputs.shape[0]
        for d in self._delayed:
            first = depth - d.steps - 1  # step k - steps - 1 of the block's first k
            out[:, d.channel] = ((d.state @ zs[:, first : first + n]).real + us[first : first + n] @ d.now
                                 + us[first + 1 : first + n + 1] @ d.next)
        self._history_z = zs[:, zs.shape[1] - depth :]
        self._history_u = us[us.shape[0] - depth :]
        return out


@dataclass(frozen=True)
class _DelayedOutput:
    """One output channel late by ``steps + 1 - theta`` steps: at step ``k`` it is the output at
    ``t_m + theta dt``, ``m = k - steps - 1``, exactly (``theta`` in (0, 1], inputs linear over
    the step): ``y = Re(state @ z_m) + now @ u_m + next @ u_{m+1}`` (``z`` modal, ``u`` all inputs).
    """

    channel: int
    steps: int
    state: np.ndarray  # (modes,)
    now: np.ndarray  # (inputs,)
    next: np.ndarray  # (inputs,)


def _delayed_output(channel: int, delay_s: float, ss: StateSpace, dt_s: float,
                    modes: np.ndarray) -> _DelayedOutput:
    """Output ``channel`` of ``ss`` late by ``delay_s``; ``modes`` maps modal states to ``w``."""
    steps = int(np.floor(delay_s / dt_s))
    theta = 1.0 - (delay_s / dt_s - steps)
    phi, g_now, g_ramp = ramp_response(ss.a, ss.b, dt_s, theta)
    g = foh_input_shift(ss.a, ss.b, dt_s)
    c, d = ss.c[channel], ss.d[channel]
    # xi(t_m + theta dt) = phi (w_m + g u_m) + g_now u_m + g_ramp (u_{m+1} - u_m); y = c xi + d u
    return _DelayedOutput(channel, steps, state=c @ phi @ modes, now=c @ (phi @ g + g_now - g_ramp)
                          + d * (1.0 - theta), next=c @ g_ramp + d * theta)


def free_decay(vehicle: Vehicle, x0: np.ndarray, dt_s: float, n: int) -> np.ndarray:
    """Sensor accelerations of the free decay from state ``x0`` on a flat road."""
    return HalfCarPlant(vehicle, dt_s, x0=x0).run(np.zeros((n, 2)))


def natural_modes(v: Vehicle) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], damping ratio) of the four modes, sorted by frequency."""
    return natural_modes_of(state_space(v))
