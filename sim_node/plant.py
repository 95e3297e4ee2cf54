"""A linear vehicle model run block by block, with the simulator's departures from it.

Run for every vehicle (:mod:`sim_node.vehicle_plant`): each is ``M q'' + C q' + K q = Kt u + Ct u'``
(:mod:`sim_node.modal`) with corners whose suspension acts along rows ``G`` of ``q`` (the
extensions ``e = G q``), outputs that read the body's acceleration at the sensors, and the
departures of :mod:`sim_node.departures`:

- A nonlinear suspension: each corner's tension is the linear ``k e + c v`` plus an extra
  ``f(e, v)``, one more input per corner in the same exact discretisation, piecewise linear
  between steps like the road. A block's ``f`` is the fixed point of "run the linear model
  on the road and ``f`` (vectorised), read ``e, v`` off its states, evaluate ``f``"
  (:mod:`sim_node.fixed_point`), to ``TENSION_RTOL``. For the asymmetric dampers (slope
  ``a c``, ``a = (ratio - 1)/(ratio + 1)``, on a port whose admittance the damper ``c``
  bounds by ``1/c``) it contracts by ``|a|`` per iteration; for the springs while
  ``3 p (e/e_ref)^2`` is moderate. The fixed point is unique, so blocks cut anywhere give
  the same run; what is left is the first-order hold of ``f``, second order in the step
  (``test_halfcar``, ``test_fullcar``: against an ODE solver).
- Delayed sensors (``delays_s``, one per output): the output a fraction of a step after an
  earlier step, exact too (the augmented exponential over that fraction), from the states
  and inputs of the last steps, kept across blocks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve

from sim_node.departures import SuspensionLaw
from sim_node.fixed_point import solve_fixed_point
from sim_node.modal import (
    ModalPropagator,
    SecondOrderModel,
    StateSpace,
    foh_input_shift,
    ramp_response,
    state_space_of,
)

TENSION_RTOL = 1e-12  # the fixed point's tolerance, share of the largest extra tension
TENSION_ATOL_N = 1e-9  # ... and in newtons (a block at rest)
MAX_ITERATIONS = 100  # per block
DENSE_STEPS = 256  # blocks up to this many steps solve their tensions with a response matrix
NOT_CONVERGED = ("departures: the nonlinear suspension did not converge; use a damper_ratio closer to 1, a "
                 "smaller spring_progression or a larger spring_reference_m")


def with_tension_inputs(ss: StateSpace, model: SecondOrderModel, corners: np.ndarray,
                        body_rows: np.ndarray, rates: np.ndarray | None = None) -> StateSpace:
    """``ss`` with the corners' extra suspension tensions [N] as more inputs, after the road's.

    A tension ``f`` pulls body and wheel together: generalised force ``-G^T f`` (eq 3-3's
    right-hand side, ``G = corners``), no derivative input, and a direct path to the body's
    accelerations (``body_rows @ q''``; none to a rate, a gyro's: ``rates``).
    """
    n, k = model.dof, corners.shape[0]
    accel = -solve(model.mass, corners.T, assume_a="diagonal")  # (dof, corners) q'' per newton
    b = np.vstack([np.zeros((n, k)), accel])
    direct = body_rows @ accel
    if rates is not None:
        direct[rates] = 0.0
    return StateSpace(a=ss.a, b=np.hstack([ss.b, b]), c=ss.c, d=np.hstack([ss.d, direct]),
                      shift=np.hstack([ss.shift, np.zeros((2 * n, k))]))


class SuspendedPlant:
    """The exact-discretised model, propagated block by block, with its departures.

    Args:
        model: the second-order model (road displacement under each tyre in).
        body_rows: (outputs, dof) rows reading the body's acceleration at the sensors.
        rates: (outputs,) bool: these outputs read their row's rate instead (a gyro; None: none).
        corners: (corners, dof) the suspension's extension rows ``G``.
        dt_s: simulation step [s]; the road is piecewise linear between steps.
        x0: initial physical state ``[q, q']`` (default: at rest, zero road).
        u0: road displacement at the first step, for the state shift [m].
        suspension: the suspension's nonlinear part (None: linear).
        delays_s: each output's delay behind its step [s], >= 0 (empty: none). Before the
            first step the plant is taken as having held ``x0`` (an approximation for the
            first ``delay`` of a run; the simulator's settling time covers it).
        what: the model's name, for error messages.
    """

    def __init__(self, model: SecondOrderModel, body_rows: np.ndarray, corners: np.ndarray, dt_s: float,
                 x0: np.ndarray | None = None, u0: np.ndarray | None = None,
                 suspension: SuspensionLaw | None = None, delays_s: Sequence[float] = (),
                 what: str = "plant", rates: np.ndarray | None = None) -> None:
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
        if not all(d >= 0.0 for d in delays_s):
            raise ValueError(f"delays_s must be >= 0, got {tuple(delays_s)!r}")
        self.dt_s = float(dt_s)
        self.n_road = model.tyre_stiffness.shape[1]
        n_state = 2 * model.dof
        ss = state_space_of(model, body_rows, rates)
        if suspension is not None:
            ss = with_tension_inputs(ss, model, corners, body_rows, rates)
        self._modal = p = ModalPropagator(ss, self.dt_s, what)
        x0 = np.zeros(n_state) if x0 is None else np.asarray(x0, dtype=float)
        u0 = np.zeros(self.n_road) if u0 is None else np.asarray(u0, dtype=float)
        if x0.shape != (n_state,) or u0.shape != (self.n_road,):
            raise ValueError(f"x0 must have shape ({n_state},) and u0 ({self.n_road},), got {x0.shape}, "
                             f"{u0.shape}")
        self._law = suspension
        self._response: tuple[int, np.ndarray] | None = None
        self.iterations = 0  # linear runs the last block's fixed point took (0: a linear plant)
        if suspension is not None:
            # the corners' [e, v] from the modal state and the inputs
            motion = np.kron(np.eye(2), corners)
            self._motion_modal = p.project(motion)
            self._motion_direct = motion @ p.foh_shift
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
            road_m: (n, tyres) road displacement under each tyre at steps k, k+1, … [m]; the
                first row is the road at the current state's time.

        Returns:
            (n, outputs) body vertical acceleration at the sensors at those steps (each
            less its delay) [m/s^2], gravity excluded.

        Raises:
            ConfigError: the nonlinear suspension's iteration did not converge.
        """
        u = np.asarray(road_m, dtype=float)
        if u.ndim != 2 or u.shape[1] != self.n_road:
            raise ValueError(f"road_m must have shape (n, {self.n_road}), got {u.shape}")
        n = u.shape[0]
        if n == 0:
            return np.zeros((0, self._modal.dd.shape[0]))
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
        """The block's inputs ``[road, extra tension]`` at the fixed point, and its states.

        The corners' motion ``[e, v]`` is the road's response (once) plus the tensions' from
        rest: per iteration one linear run (vectorised), or for short blocks (the node's) one
        product with the block's response matrix, which skips the per-call overhead of the
        filters.
        """
        n, r = road.shape
        law = self._law
        assert law is not None
        z_road = self._modal.propagate((road @ self._modal.in_modal[:, :r].T).T, self._z)
        motion_road = (self._motion_modal @ z_road[:, :n]).real + self._motion_direct[:, :r] @ road.T
        drive, direct = self._modal.in_modal[:, r:], self._motion_direct[:, r:]
        rest = np.zeros_like(self._z)
        response = self._tension_response(n) if n <= DENSE_STEPS else None
        k = drive.shape[1]

        def tensions(tension: np.ndarray) -> tuple[np.ndarray, None]:  # (corners, n) -> (corners, n)
            if response is not None:
                motion = motion_road + (response @ tension.ravel()).reshape(2 * k, n)
            else:
                z = self._modal.propagate(drive @ tension, rest)
                motion = motion_road + (self._motion_modal @ z[:, :n]).real + direct @ tension
            return law.extra_tension_n(motion[:k].T, motion[k:].T).T, None

        guess = np.repeat(self._tension[:, None], n, axis=1)  # the last step's, held
        solved = solve_fixed_point(tensions, guess, rtol=TENSION_RTOL, atol=TENSION_ATOL_N,
                                   max_evaluations=MAX_ITERATIONS, failure=NOT_CONVERGED)
        self.iterations = solved.evaluations
        self._tension = solved.x[:, -1].copy()
        return np.hstack([road, solved.x.T]), z_road + self._modal.propagate(drive @ solved.x, rest)

    def _tension_response(self, n: int) -> np.ndarray:
        """(2 k n, k n) map from a block's tensions (k, n) to the corners' motion they cause from
        rest (2 k, n): block lower-triangular Toeplitz in the Markov parameters (kept per ``n``)."""
        if self._response is None or self._response[0] != n:
            drive = self._modal.in_modal[:, self.n_road:]
            k = drive.shape[1]
            powers = self._modal.lam[None, :] ** np.arange(n - 1)[:, None]  # (n - 1, modes)
            markov = np.einsum("qm,im,mr->iqr", self._motion_modal, powers, drive).real
            lag = np.subtract.outer(np.arange(n), np.arange(n)) - 1  # k - j - 1; < 0: no effect yet
            blocks = np.concatenate([markov, np.zeros((1, 2 * k, k))])[np.where(lag >= 0, lag, n - 1)]
            blocks[np.arange(n), np.arange(n)] = self._motion_direct[:, self.n_road:]  # same step: FOH shift
            self._response = (n, blocks.transpose(2, 0, 3, 1).reshape(2 * k * n, k * n))
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


__all__ = ["DENSE_STEPS", "NOT_CONVERGED", "SuspendedPlant", "with_tension_inputs"]
