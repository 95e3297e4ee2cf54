"""The fits' trust-region Newton iterations (:class:`Fits`): from several starts, the lowest ℓ
kept; each first in the fast mode (derivatives at the model's nodes, see
:class:`WhittleObjective`), then at every bin where that does not converge; the stopping
rules (the Newton decrement over the parameters not at a boundary, a stall).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import OptimizeResult, minimize

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.covariance import NOISE_AT_ZERO
from rozyn_estimator.method.likelihood.objective import WhittleObjective

_FAST_ITERATIONS = 30  # the fast iterations' share of max_iter (noisy data converge in ~5-25)
_STALL_ITERATIONS = 10  # iterations without progress that end a fit (see _stalled)
_STALLED_TOL = 100.0  # a stalled fit counts as converged with its decrement below this many tol


def noise_share(theta: np.ndarray, objective: WhittleObjective) -> np.ndarray:
    """(front, rear) fitted noise floor, share of each channel's power in the band."""
    return np.exp(theta[4:6]) / objective.band_power


class Fits:
    """Trust-region Newton fits from several starts; keeps the lowest ℓ."""

    def __init__(self, objective: WhittleObjective, cfg: LikelihoodConfig, tol: float) -> None:
        self.objective, self.cfg, self.tol = objective, cfg, tol
        self.best: OptimizeResult | None = None
        self.iterations = self.starts = 0
        self.converged = False

    def run(self, theta0: np.ndarray) -> None:
        """A fit from ``theta0``: the fast iterations (derivatives at the model's nodes); where
        they do not converge (nearly noise-free data: S nearly singular, and the Fisher
        information at every grid step's centre bin a poor guide), on at every bin."""
        res, stalled = self._minimize(theta0, True, min(_FAST_ITERATIONS, self.cfg.max_iter))
        if np.isfinite(res.fun) and self._decrement(res.x) >= self.tol * (_STALLED_TOL if stalled else 1.0):
            more, stalled = self._minimize(res.x, False, max(1, self.cfg.max_iter - int(res.nit)))
            more.nit += res.nit
            res = more if np.isfinite(more.fun) and more.fun <= res.fun else res
        self.iterations += int(res.nit)
        self.starts += 1
        if np.isfinite(res.fun) and (self.best is None or res.fun < self.best.fun):
            self.best = res
            # stalled within a few tol of the optimum: as good as the quadratic model can say
            self.converged = self._decrement(res.x) < self.tol * (_STALLED_TOL if stalled else 1.0)

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
