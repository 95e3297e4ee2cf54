"""The fits' trust-region Newton iterations (:class:`Fits`): from several starts, the lowest ℓ
kept; each first in the fast mode (derivatives at the model's nodes, see
:class:`WhittleObjective`), then at every bin where that does not converge; the stopping
rules (the Newton decrement over the parameters not at a boundary, a stall).

A warm start (the previous window's optimum) is usually one step from this window's: its
first step is taken as scipy's trust region would take it (the Newton step when it lies
within the initial trust radius, accepted when ℓ falls by more than ``_ACCEPT`` of what the
quadratic model predicts), but the proposed point is evaluated at every bin at once, where
the convergence test and the calibration that follows need it anyway: the fast mode's
evaluation there and the optimiser's set-up are saved (measured on the full windows of
drives: 3-4 ms of a warm update's 22-30 ms offline; the estimates within 0.002 of their std).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve
from scipy.optimize import OptimizeResult, minimize

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.covariance import NOISE_AT_ZERO
from rozyn_estimator.method.likelihood.objective import WhittleObjective

_FAST_ITERATIONS = 30  # the fast iterations' share of max_iter (noisy data converge in ~5-25)
_STALL_ITERATIONS = 10  # iterations without progress that end a fit (see _stalled)
_STALLED_TOL = 100.0  # a stalled fit counts as converged with its decrement below this many tol
_TRUST = 1.0  # a warm start's first step: at most this long (scipy's initial trust radius)
_ACCEPT = 0.15  # ... and taken when ℓ falls by more than this share of the predicted fall (its eta)
_NEAR_STEPS = 10.0  # on at every bin from there when its Newton decrement is below this (a step or
# two: each costs more than a fast one), else in the fast mode (a start far off, e.g. the road changed)


def noise_share(theta: np.ndarray, objective: WhittleObjective) -> np.ndarray:
    """(front, rear) fitted noise floor, share of each channel's power in the band."""
    return np.exp(theta[4:6]) / objective.band_power


_REVIVE_SHARES = 10.0 ** np.arange(-8, 0)  # the floors tried for one run aground, share of its power


def aground(fun: Callable[[np.ndarray], float], jac: Callable[[np.ndarray], np.ndarray],
            theta: np.ndarray, value: float, noise: slice, power: np.ndarray) -> np.ndarray | None:
    """A start for a fit whose noise floor ran aground: θ with that floor at the best of a few
    levels, where that beats the fit's optimum ``value`` at ``theta`` (else None).

    A floor is its log in θ, and at a floor far below its channel's power the likelihood's
    gradient in it vanishes: a fit that wandered there (a poor start, on noisy data) cannot
    come back, and ends in a wrong basin with that channel noise-free (the model check then
    rightly warns). Such a floor's likelihood still falls as the floor itself grows (the
    gradient in the floor, not its log, is negative where raising it to 1e-4 of its channel's
    power would gain a nat): only those are tried, so noise-free data cost one gradient."""
    floors = np.exp(theta[noise])
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = jac(theta)[noise] / floors  # ∂ℓ/∂n: the chain rule's factor n taken out
    stuck = np.flatnonzero((floors < 1e-4 * power) & (slope * 1e-4 * power < -1.0))
    start, best = None, value
    for i in stuck:
        for share in _REVIVE_SHARES:
            trial = theta.copy()
            trial[noise.start + i] = math.log(share * power[i])
            f = fun(trial)
            if np.isfinite(f) and f < best:
                start, best = trial, f
    return start


class Fits:
    """Trust-region Newton fits from several starts; keeps the lowest ℓ."""

    def __init__(self, objective: WhittleObjective, cfg: LikelihoodConfig, tol: float) -> None:
        self.objective, self.cfg, self.tol = objective, cfg, tol
        self.best: OptimizeResult | None = None
        self.iterations = self.starts = 0
        self.converged = False

    def run(self, theta0: np.ndarray, warm: bool = False) -> None:
        """A fit from ``theta0``: the fast iterations (derivatives at the model's nodes); where
        they do not converge (nearly noise-free data: S nearly singular, and the Fisher
        information at every grid step's centre bin a poor guide), on at every bin. ``warm``:
        ``theta0`` is near the optimum (the previous window's): its first step is taken
        directly (:meth:`_warm_step`) to a point evaluated at every bin, where the fit ends
        when it has converged, and goes on at every bin when it is near (cheaper than the fast
        mode's evaluating the point again), else as from a cold start."""
        first = self._warm_step(theta0) if warm else None
        carried = 0  # the warm step's iterations, where the fast iterations go on from it
        if first is not None and self._decrement(first.x) < _NEAR_STEPS:
            res, stalled = first, False  # evaluated at every bin: converged, or on at every bin
        else:  # cold, or a warm start further off than the previous window's optimum would be
            carried = 0 if first is None else int(first.nit)
            res, stalled = self._minimize(theta0 if first is None else first.x, True,
                                          min(_FAST_ITERATIONS, self.cfg.max_iter))
        if np.isfinite(res.fun) and self._decrement(res.x) >= self.tol * (_STALLED_TOL if stalled else 1.0):
            more, stalled = self._minimize(res.x, False, max(1, self.cfg.max_iter - int(res.nit)))
            more.nit += res.nit
            res = more if np.isfinite(more.fun) and more.fun <= res.fun else res
        res.nit += carried
        self.iterations += int(res.nit)
        self.starts += 1
        if np.isfinite(res.fun) and (self.best is None or res.fun < self.best.fun):
            self.best = res
            # stalled within a few tol of the optimum: as good as the quadratic model can say
            self.converged = self._decrement(res.x) < self.tol * (_STALLED_TOL if stalled else 1.0)

    def _warm_step(self, theta0: np.ndarray) -> OptimizeResult | None:
        """The first step from a warm start as scipy's trust region takes it (module
        docstring): the fast mode's gradient and Hessian at ``theta0``, the point evaluated at
        every bin. None where it would not be the Newton step, or is not accepted."""
        self.objective.fast = True
        try:
            value, grad = self.objective.evaluate(theta0)
            hess = self.objective.hess(theta0) if np.isfinite(value) else None
        finally:
            self.objective.fast = False
        if hess is None:
            return None
        try:
            step = -cho_solve(cho_factor(hess), grad)
        except (LinAlgError, ValueError):  # not positive definite (or finite): the trust region decides
            return None
        predicted = -(grad @ step + 0.5 * step @ hess @ step)
        if not (np.linalg.norm(step) <= _TRUST and predicted > 0):
            return None
        theta1 = theta0 + step
        value1 = self.objective.fun(theta1)
        if not (np.isfinite(value1) and value - value1 > _ACCEPT * predicted):
            return None
        return OptimizeResult(x=theta1, fun=value1, nit=1)

    def continued(self, objective: WhittleObjective) -> Fits:
        """These fits continued on another objective (the same θ): from the best point."""
        assert self.best is not None
        more = Fits(objective, self.cfg, self.tol)
        more.run(self.best.x)
        more.iterations += self.iterations
        more.starts = self.starts
        return more

    def _minimize(self, theta0: np.ndarray, fast: bool, max_iter: int) -> tuple[OptimizeResult, bool]:
        """The trust-region Newton iterations from ``theta0``: (result, whether they stalled)."""
        values: list[float] = []
        started: list[bool] = []

        def stop_when_converged(intermediate_result: OptimizeResult) -> None:
            values.append(float(intermediate_result.fun))
            if self._decrement(intermediate_result.x) < self.tol or _stalled(values, self.tol):
                raise StopIteration

        def hess(theta: np.ndarray) -> np.ndarray:
            # scipy's trust region takes the Hessian with each proposed point, before its
            # callback. Where the fit has converged it is never used (the step is taken and
            # the callback stops, or it is rejected): the Fisher information (already there)
            # stands in for the sharper Hessian's exact rows. The start's is always used.
            if started and self._decrement(theta) < self.tol:
                return self.objective.fisher(theta)
            started.append(True)
            return self.objective.hess(theta)

        self.objective.fast = fast
        try:
            res = minimize(self.objective.fun, theta0, jac=self.objective.jac, hess=hess,
                           method="trust-exact", callback=stop_when_converged,
                           options={"gtol": 1e-12, "maxiter": max_iter})
            stalled = _stalled(values, self.tol)
        finally:
            self.objective.fast = False
        return res, stalled

    def _decrement(self, theta: np.ndarray) -> float:
        """The Newton decrement over the parameters not at a boundary: a noise floor run to
        zero (noise-free data) keeps creeping down without changing anything else."""
        free = np.ones(theta.size, dtype=bool)
        free[4:6] = noise_share(theta, self.objective) > NOISE_AT_ZERO
        return self.objective.decrement(theta, free)


def _stalled(values: list[float], tol: float) -> bool:
    """ℓ improved by less than a tenth of ``tol`` over the last ten iterations: on a short
    window the fit can crawl along a flat direction (the Hessian is the Fisher information
    with a few exact rows, not the observed one) by 1e-5 an iteration while the decrement
    stays just above ``tol``."""
    return len(values) > _STALL_ITERATIONS and values[-1 - _STALL_ITERATIONS] - values[-1] < 0.1 * tol
