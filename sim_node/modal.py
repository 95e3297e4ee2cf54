"""Linear vehicle models ``M q'' + C q' + K q = Kt u + Ct u'`` and their exact, streaming discretisation.

Run for every vehicle by :mod:`sim_node.vehicle_plant`.

The road enters through the tyres as displacement (tyre stiffness) and velocity (tyre
damping). The road displacement is taken piecewise linear between simulation steps
(first-order hold), so the discretisation is exact for it: the damping term's derivative
input is removed by a state shift and the result discretised with
``scipy.signal.cont2discrete(method="foh")``. Blocks are propagated in modal coordinates
with one first-order ``lfilter`` per mode, so there is no Python loop per sample, and the
state carries over so a long run equals the concatenation of blocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, solve
from scipy.signal import cont2discrete, lfilter

from rozyn_estimator.body_model import SecondOrderModel


@dataclass(frozen=True)
class StateSpace:
    """``xi' = a xi + b u``, ``y = c xi + d u`` with ``xi = x - shift @ u``.

    ``x = [q, q']`` (eq 3-2); ``y`` the body accelerations at the sensors [m/s^2]. The
    shift removes the road-velocity input so ``u`` is the road displacement only.
    """

    a: np.ndarray  # (2 dof, 2 dof) eq 3-11
    b: np.ndarray  # (2 dof, inputs)
    c: np.ndarray  # (outputs, 2 dof)
    d: np.ndarray  # (outputs, inputs)
    shift: np.ndarray  # (2 dof, inputs)


def state_space_of(m: SecondOrderModel, body_rows: np.ndarray, rates: np.ndarray | None = None) -> StateSpace:
    """Continuous state space with road displacement as input and, as outputs, the
    accelerations ``body_rows @ q''`` (rows that read the body only, no wheel); where
    ``rates`` is set, the rates ``body_rows @ q'`` instead (a gyro)."""
    n = m.dof
    minv_k = solve(m.mass, m.stiffness, assume_a="diagonal")
    minv_c = solve(m.mass, m.damping, assume_a="diagonal")
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-minv_k, -minv_c]])  # eq 3-11
    tyres = m.tyre_stiffness.shape[1]
    b0 = np.vstack([np.zeros((n, tyres)), solve(m.mass, m.tyre_stiffness, assume_a="diagonal")])
    b1 = np.vstack([np.zeros((n, tyres)), solve(m.mass, m.tyre_damping, assume_a="diagonal")])
    c = body_rows @ a[n:, :]  # body rows carry no direct road input
    if rates is not None and np.any(rates):  # q' is the state's second half
        c[rates] = np.hstack([np.zeros_like(body_rows[rates]), body_rows[rates]])
    return StateSpace(a=a, b=a @ b1 + b0, c=c, d=c @ b1, shift=b1)


def static_state_of(m: SecondOrderModel, road_m: np.ndarray) -> np.ndarray:
    """State ``x = [q, q']`` at rest on a road held at ``road_m`` (one height per tyre) [m]."""
    q = solve(m.stiffness, m.tyre_stiffness @ np.asarray(road_m, dtype=float))
    return np.concatenate([q, np.zeros(m.dof)])


class ModalPropagator:
    """A state space discretised exactly (FOH) and diagonalised, for block-wise runs.

    The state is real, so conjugate modes carry conjugate coordinates: one of each pair
    is propagated (``lam``) and counted twice in every output (:meth:`project`).

    Args:
        ss: the continuous state space.
        dt_s: the step [s]; inputs are piecewise linear between steps.
        what: the model's name, for the error message.

    Raises:
        ValueError: the transition matrix is not diagonalisable (repeated poles).
    """

    def __init__(self, ss: StateSpace, dt_s: float, what: str) -> None:
        ad, bd, cd, dd, _ = cont2discrete((ss.a, ss.b, ss.c, ss.d), dt_s, method="foh")
        # scipy's FOH state is xi - g @ u; recover g to map physical states in and out.
        self.foh_shift = ss.shift + foh_input_shift(ss.a, ss.b, dt_s)
        eigvals, modes = np.linalg.eig(ad)
        if np.linalg.cond(modes) > 1e10:
            raise ValueError(f"{what} transition matrix is not diagonalisable (repeated poles)")
        self.modes = modes
        self.keep = eigvals.imag >= 0.0
        self.weight = np.where(eigvals[self.keep].imag > 0.0, 2.0, 1.0)
        self.lam = eigvals[self.keep]
        self.to_modal = np.linalg.inv(modes)[self.keep]
        self.in_modal = self.to_modal @ bd
        self.out_modal = self.project(cd)
        self.dd = dd

    def project(self, rows: np.ndarray) -> np.ndarray:
        """Rows reading the physical state ``x``, as rows reading the kept modal state."""
        return (rows @ self.modes)[:, self.keep] * self.weight

    def modal_state(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The modal state of physical state ``x`` with inputs ``u`` at the same step."""
        return self.to_modal @ (x - self.foh_shift @ u)

    def propagate(self, drive: np.ndarray, start: np.ndarray) -> np.ndarray:
        """Modal states at the block's steps and after it, (modes, n + 1), from ``start`` and
        ``drive`` (modes, n)."""
        n = drive.shape[1]
        z = np.empty((self.lam.size, n + 1), dtype=complex)
        z[:, 0] = start
        for j, lam in enumerate(self.lam):
            # z[k+1] = lam z[k] + drive[k], one C loop per mode
            z[j, 1:] = lfilter([1.0], [1.0, -lam], drive[j], zi=[lam * start[j]])[0]
        return z

    def run(self, u: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Outputs (n, outputs) of a block of inputs ``u`` (n, inputs) from modal state ``start``,
        and the modal states (modes, n + 1)."""
        z = self.propagate((u @ self.in_modal.T).T, start)
        return self.output(z[:, : u.shape[0]], u), z

    def output(self, z: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Outputs (n, outputs) at modal states ``z`` (modes, n) with inputs ``u`` (n, inputs)."""
        return (self.out_modal @ z).real.T + u @ self.dd.T


def ramp_response(a: np.ndarray, b: np.ndarray, dt_s: float, fraction: float) -> tuple[np.ndarray, ...]:
    """``(phi, g_now, g_ramp)``: ``xi(s dt) = phi xi_0 + g_now u_0 + g_ramp (u_1 - u_0)`` at
    ``s = fraction`` for ``xi' = a xi + b u`` with ``u`` linear from ``u_0`` (s = 0) to ``u_1`` (s = 1)."""
    n, m = b.shape
    em = np.zeros((n + 2 * m, n + 2 * m))
    em[:n, :n] = a * dt_s
    em[:n, n : n + m] = b * dt_s
    em[n : n + m, n + m :] = np.eye(m)
    e = expm(em * fraction)
    return e[:n, :n], e[:n, n : n + m], e[:n, n + m :]


def foh_input_shift(a: np.ndarray, b: np.ndarray, dt_s: float) -> np.ndarray:
    """The ``g`` of scipy's FOH discretisation (its state is ``xi - g u``): the ramp's response."""
    return ramp_response(a, b, dt_s, 1.0)[2]


def natural_modes_of(ss: StateSpace) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], damping ratio) of the oscillating modes, sorted by frequency."""
    lam = np.linalg.eigvals(ss.a)
    lam = lam[lam.imag > 0]
    wn = np.abs(lam)
    order = np.argsort(wn)
    return wn[order] / (2 * np.pi), (-lam.real / wn)[order]
