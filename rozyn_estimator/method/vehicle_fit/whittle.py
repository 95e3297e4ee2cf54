"""The Whittle objective (:class:`WhittleObjective`, either car): ℓ(θ), its gradient and the Fisher
information for stacks of k×k spectral matrices:

``ℓ(θ) = Σ_k log det S_k + tr(S_k⁻¹ I_k)`` over the band's Fourier
frequencies, ``∂_i ℓ = Σ_k tr((S⁻¹ - S⁻¹ I S⁻¹) ∂_i S)`` and the Fisher information
``F_ij = Σ_k tr(S⁻¹ ∂_i S S⁻¹ ∂_j S)``. With the Cholesky factor ``S = L Lᴴ`` the latter is
the real inner product of the whitened derivatives ``W_i = L⁻¹ ∂_i S L⁻ᴴ`` (Hermitian):
``tr(W_i W_j) = Σ W_i ⊙ conj(W_j)`` — one matrix product for all pairs.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import OptimizeResult, minimize

from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.stacks import herm, inverse_cholesky, mul

_HESSIAN_STEP = 3  # the optimiser's Fisher information: every 3rd frequency (class docstring)
_HESSIAN_MIN = 300  # ... of models with at least this many frequencies
# a fit for the body parameters converges once their step is below the tolerance and the
# whole decrement below this: ℓ within 0.05 nats, the nuisances' quadratic model trusted
_NUISANCE_DECREMENT = 0.1
_FLOOR_RISE = 2.0  # a line-search step raises a noise floor's log by at most this (_line_scoring)
_FLOOR_FALL = 30.0  # ... and lowers it by at most this (a floor e^-30 of where it was is at zero)
_BACKTRACKS = (1.0, 0.3, 0.09, 0.027)  # the step lengths a line search tries
_PENDING = np.zeros((0, 0, 0, 0), dtype=complex)  # dS at the nodes not computed yet (WhittleObjective.fun)


class WhittleObjective:
    """ℓ(θ), ∇ℓ and the Fisher information of a window's periodogram matrices (cached at the
    last θ).

    The model is evaluated at its nodes and mapped to the periodograms' frequencies
    (:meth:`VehicleSpectrum.to_targets`); the gradient maps back the other way (the map's
    adjoint: one matrix per frequency instead of one per parameter), and the optimiser's
    Hessian is the Fisher information summed over every ``_HESSIAN_STEP``-th frequency, each
    standing for its neighbours (it is smooth in frequency: it shapes the steps, the gradient
    decides where they end); the refinement publishes it too (:meth:`information`), and
    :meth:`fisher` is the whole sum.

    Args:
        model: the full car's spectral model at the periodograms' frequencies.
        periodogram: (K, k, k) the window's periodogram matrices (:func:`window_spectra`), or
            their means over groups of neighbouring bins.
        counts: (K,) the bins each mean stands for (default: one each): a mean of ``c``
            bins counts ``c`` times (its Wishart likelihood has ``c`` degrees of freedom).
        precision: (n_params,) Gaussian priors' precisions ``1/σ²`` on θ about zero (0: none):
            ℓ, ∇ℓ and the optimiser's Hessian are the posterior's; :meth:`fisher` stays the data's.
    """

    def __init__(self, model: VehicleSpectrum, periodogram: np.ndarray,
                 counts: np.ndarray | None = None, precision: np.ndarray | None = None) -> None:
        self.model, self.periodogram = model, periodogram
        self.precision = np.zeros(model.n_params) if precision is None else np.asarray(precision, dtype=float)
        self.counts = np.ones(periodogram.shape[0]) if counts is None else np.asarray(counts, dtype=float)
        self._root_counts = np.sqrt(self.counts)[:, None, None]
        n = periodogram.shape[0]
        self._sub = np.arange(0, n, _HESSIAN_STEP if n >= _HESSIAN_MIN else 1)
        self._sub_counts = np.add.reduceat(self.counts, self._sub)
        self._sub_root_counts = np.sqrt(self._sub_counts)[:, None, None]
        self._key: bytes | None = None
        self._value: tuple[float, np.ndarray] = (math.inf, np.zeros(model.n_params))
        self._state: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # (S, dS at the nodes, L⁻¹)
        self._dS: np.ndarray | None = None  # dS/dθ at the frequencies, when asked
        self._rows: np.ndarray | None = None
        self._hessian: np.ndarray | None = None
        self._sampled_rows: np.ndarray | None = None
        self._S_nodes: np.ndarray | None = None  # S at the model's nodes at the last evaluation
        self._theta = np.zeros(model.n_params)  # ... its θ
        self._inv: np.ndarray | None = None  # ... and S⁻¹ at the frequencies
        self._kernels: tuple[tuple[bytes, bytes], np.ndarray] | None = None  # (θ, combos), score_kernels

    def nll(self, S: np.ndarray) -> float:
        """ℓ for a model spectrum ``S`` (inf where it is not positive definite)."""
        factor = inverse_cholesky(S)
        return math.inf if factor is None else self._nll(factor)

    def _nll(self, linv: np.ndarray, inv: np.ndarray | None = None) -> float:
        """ℓ from ``L⁻¹`` (and ``S⁻¹ = L⁻ᴴ L⁻¹`` where at hand): ``tr(S⁻¹ I)`` as one sum over
        both indices (numpy's matmul loops over a stack of tiny matrices: the products
        ``L⁻¹ I L⁻ᴴ`` took 0.9 ms for 1741 2x2s, the sum 0.03 ms)."""
        log_det = -2.0 * np.log(np.einsum("kaa->ka", linv).real).sum(axis=1)
        inv = mul(herm(linv), linv) if inv is None else inv
        fit = np.einsum("kab,kba->k", inv, self.periodogram).real
        return float(self.counts @ (log_det + fit))

    def evaluate(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """(ℓ, ∇ℓ) at θ; ℓ = inf where S is not positive definite."""
        key = np.asarray(theta, dtype=float).tobytes()
        if key != self._key:
            S_nodes, dS = self.model.node_spectrum(theta)
            assert dS is not None
            return self._store(key, np.asarray(theta, dtype=float), S_nodes, dS)
        if self._state is not None and self._state[1] is _PENDING:  # ℓ alone so far (:meth:`fun`)
            _, dS = self.model.node_spectrum(theta)
            assert dS is not None
            self._complete(dS)
        return self._value

    def fun(self, theta: np.ndarray) -> float:
        """ℓ at θ. Its gradient and the derivatives of S wait until asked for (:meth:`evaluate`):
        a line search's rejected trial and a floor's probe need none, and they are two thirds of
        an evaluation's work."""
        key = np.asarray(theta, dtype=float).tobytes()
        if key != self._key:
            S_nodes, _ = self.model.node_spectrum(theta, derivatives=False)
            self._store(key, np.asarray(theta, dtype=float), S_nodes, None)
        return self._value[0]

    def seed(self, theta: np.ndarray, S_nodes: np.ndarray, dS_nodes: np.ndarray) -> None:
        """Take S and dS/dθ at θ's nodes as given (an evaluation of an equal model: the
        calibration's posterior starts where the fit ended), as :meth:`evaluate` would."""
        theta = np.asarray(theta, dtype=float)
        self._store(theta.tobytes(), theta, S_nodes, dS_nodes)

    def evaluated(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(S, dS/dθ) at θ's nodes (raises ValueError where S is not positive definite)."""
        self.factored(theta)
        assert self._S_nodes is not None and self._state is not None
        return self._S_nodes, self._state[1]

    def _store(self, key: bytes, theta: np.ndarray, S_nodes: np.ndarray,
               dS: np.ndarray | None) -> tuple[float, np.ndarray]:
        """ℓ at θ from S at the nodes, and ∇ℓ from ``dS`` (None: when :meth:`evaluate` asks)."""
        S = self.model.to_targets(S_nodes)
        linv = inverse_cholesky(S)
        self._key, self._dS, self._rows, self._hessian, self._sampled_rows = key, None, None, None, None
        self._S_nodes, self._theta = S_nodes, theta
        if linv is None:
            self._state, self._value = None, (math.inf, np.zeros(self.model.n_params))
            return self._value
        self._inv = inv = mul(herm(linv), linv)
        value = self._nll(linv, inv) + 0.5 * float(self.precision @ theta**2)
        self._state, self._value = (S, _PENDING, linv), (value, np.zeros(self.model.n_params))
        return self._value if dS is None else self._complete(dS)

    def _complete(self, dS: np.ndarray) -> tuple[float, np.ndarray]:
        """∇ℓ at the stored θ from its ``dS`` at the nodes."""
        assert self._state is not None
        S, _, linv = self._state
        inv = self._inv
        assert inv is not None
        W = self.model.to_nodes(self.counts[:, None, None] * (inv - mul(mul(inv, self.periodogram), inv)))
        grad = (dS.reshape(dS.shape[0], -1) @ W.swapaxes(1, 2).ravel()).real  # Σ_k tr(W ∂S)
        self._state = (S, dS, linv)
        self._value = (self._value[0], grad + self.precision * self._theta)
        return self._value

    def whitened_periodogram(self, theta: np.ndarray) -> np.ndarray | None:
        """``L⁻¹ I Lᴴ⁻¹`` at θ per frequency (the identity's expectation under the model; the
        model-fit check's), None where S is not positive definite."""
        self.evaluate(theta)
        if self._state is None:
            return None
        linv = self._state[2]
        return linv @ self.periodogram @ herm(linv)

    def floor_values(self, theta: np.ndarray, channel: int, floors: np.ndarray, at: int) -> np.ndarray:
        """ℓ at θ with ``channel``'s noise floor (its log is ``θ[at]``) set to each of ``floors``
        [(m/s²)²/Hz] (inf where S would not be positive definite), from the one evaluation at θ:
        a floor adds a constant to S's diagonal at every frequency (the interpolation and the
        smoothing keep constants), so ``log det`` and ``tr(S⁻¹ I)`` follow by the rank-one update
        from ``(S⁻¹)_cc`` and ``(S⁻¹ I S⁻¹)_cc`` (Sherman-Morrison): a probe of many floors for
        the price of none."""
        value = self.fun(theta)
        floors = np.asarray(floors, dtype=float)
        if self._state is None:
            return np.full(floors.shape, math.inf)
        column = herm(self._state[2]) @ self._state[2][:, :, channel:channel + 1]  # S⁻¹'s column c
        a = column[:, channel, 0].real
        b = np.einsum("ka,kab,kb->k", column[..., 0].conj(), self.periodogram, column[..., 0]).real
        delta = floors - math.exp(theta[at])
        d = 1.0 + np.outer(delta, a)
        with np.errstate(divide="ignore", invalid="ignore"):
            change = (np.log(d) - delta[:, None] * b / d) @ self.counts
            change += 0.5 * self.precision[at] * (np.log(floors) ** 2 - theta[at] ** 2)
        return np.where(np.all(d > 0, axis=1) & np.isfinite(change), value + change, math.inf)

    def jac(self, theta: np.ndarray) -> np.ndarray:
        return self.evaluate(theta)[1]

    def node_spectrum(self, theta: np.ndarray) -> np.ndarray:
        """S at the model's nodes at θ (the evaluation's: the budget's moves and the score's
        covariance start from it)."""
        self.evaluate(theta)
        assert self._S_nodes is not None
        return self._S_nodes

    def factored(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(S, L⁻¹) at θ and the periodograms' frequencies (raises ValueError where S is not
        positive definite)."""
        self.evaluate(theta)
        if self._state is None:
            raise ValueError("the model is not positive definite at θ")
        return self._state[0], self._state[2]

    def at(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(S, dS/dθ, L⁻¹) at θ and the periodograms' frequencies (raises ValueError where S is
        not positive definite); dS mapped from the nodes once asked (every parameter's: the
        costliest map there is; :meth:`factored` where S and L⁻¹ suffice)."""
        S, linv = self.factored(theta)
        if self._dS is None:
            assert self._state is not None
            self._dS = self.model.to_targets(self._state[1])
        return S, self._dS, linv

    def whitened(self, linv: np.ndarray, dS: np.ndarray, root_counts: np.ndarray | None = None) -> np.ndarray:
        """(p, 2 K k²) real rows, ``√c L⁻¹ ∂S L⁻ᴴ``'s real and imaginary parts: ``a @ bᵀ`` is
        ``Σ c tr(W_a W_b)`` (a real matrix product: numpy's complex one with a conjugate
        transpose is far slower). The parameters ride in the matrices' columns, so that numpy
        multiplies one (k, p k) matrix per frequency, not p tiny ones (twice as fast)."""
        p, K, k, _ = dS.shape
        roots = self._root_counts if root_counts is None else root_counts
        left = mul(linv, dS.transpose(1, 2, 0, 3).reshape(K, k, p * k))  # (K, a, (p, b)): L⁻¹ ∂S
        both = mul(left.reshape(K, k * p, k), herm(linv) * roots)  # (K, (a, p), d)
        W = both.reshape(K, k, p, k).transpose(2, 0, 1, 3).reshape(p, -1)
        return np.concatenate([W.real, W.imag], axis=1)

    def rows(self, theta: np.ndarray) -> np.ndarray:
        """:meth:`whitened` rows of dS/dθ at θ (the Fisher information is ``R Rᵀ``), cached."""
        _, dS, linv = self.at(theta)
        if self._rows is None:
            self._rows = self.whitened(linv, dS)
        return self._rows

    def fisher(self, theta: np.ndarray) -> np.ndarray:
        """The Fisher information at θ (identity where S is not positive definite)."""
        self.evaluate(theta)
        if self._state is None:
            return np.eye(self.model.n_params)
        rows = self.rows(theta)
        return rows @ rows.T

    def score_kernels(self, theta: np.ndarray, combos: np.ndarray) -> np.ndarray:
        """``A = S⁻¹ (c·∂S) S⁻¹`` (q, K, k, k) at θ for the directions ``combos`` (q, n_params):
        the score's kernels the sandwich (:mod:`.score`) and the intermittency's factors
        (:mod:`.intermittency`) both sum; cached for the last θ and directions."""
        key = (np.asarray(theta, dtype=float).tobytes(), np.asarray(combos, dtype=float).tobytes())
        if self._kernels is None or self._kernels[0] != key:
            _, linv = self.factored(theta)
            assert self._state is not None
            inv = mul(herm(linv), linv)
            # the map to the frequencies is linear: the q directions mapped, not every parameter
            dS = self.model.to_targets(np.tensordot(combos, self._state[1], axes=1))
            self._kernels = (key, mul(mul(inv, dS), inv))
        return self._kernels[1]

    def information(self, theta: np.ndarray) -> np.ndarray:
        """The data's Fisher information at θ as the optimiser's Hessian sums it, over every
        ``_HESSIAN_STEP``-th frequency (:meth:`sampled_rows`; the whole sum for a short band),
        ValueError where S is not positive definite. What the refinement publishes: it is smooth
        in frequency, and the variances it gives are within 0.2 % of the whole sum's with 10 %
        sensor noise (0.8 % without noise, the roll inertia at 100 km/h) at a third of the work."""
        rows = self.sampled_rows(theta)
        return rows @ rows.T

    def hess(self, theta: np.ndarray) -> np.ndarray:
        """The optimiser's Hessian: the Fisher information over every ``_HESSIAN_STEP``-th
        frequency (class docstring; scoring), with a tiny ridge."""
        self.evaluate(theta)
        if self._state is None:
            return np.eye(self.model.n_params)
        if self._sub.size == self.counts.size:
            return ridged(self.fisher(theta)) + np.diag(self.precision)
        if self._hessian is None:
            rows = self.sampled_rows(theta)
            self._hessian = ridged(rows @ rows.T) + np.diag(self.precision)
        return self._hessian

    def sampled_rows(self, theta: np.ndarray) -> np.ndarray:
        """:meth:`rows` over every ``_HESSIAN_STEP``-th frequency, each counting for its
        neighbours (as the optimiser's Hessian), cached; :meth:`rows` for a short band."""
        if self._sub.size == self.counts.size:
            return self.rows(theta)
        self.evaluate(theta)
        if self._state is None:
            raise ValueError("the model is not positive definite at θ")
        if self._sampled_rows is None:
            _, dS_nodes, linv = self._state
            self._sampled_rows = self.sampled(dS_nodes, linv)
        return self._sampled_rows

    def sampled_frequencies(self) -> tuple[np.ndarray, np.ndarray]:
        """(indices, counts): :meth:`sampled_rows`' frequencies among the periodograms' and the bins
        each stands for (its own and its neighbours'; every frequency of a short band)."""
        return self._sub, self._sub_counts

    def sampled_model(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(S, dS/dθ, what each frequency counts for) over :meth:`sampled_rows`' frequencies."""
        S, _ = self.factored(theta)
        assert self._state is not None
        at, counts = self.sampled_frequencies()
        if at.size == self.counts.size:  # every frequency: no selection to copy
            return S, self.model.to_targets(self._state[1]), counts
        return S[at], self.model.to_targets(self._state[1], at), counts

    def sampled(self, changes: np.ndarray, linv: np.ndarray) -> np.ndarray:
        """:meth:`whitened` rows of ``changes`` (p, nodes, k, k) of S at the model's nodes, over
        the frequencies of :meth:`sampled_rows` (``linv`` at every frequency)."""
        if self._sub.size == self.counts.size:
            return self.whitened(linv, self.model.to_targets(changes))
        at = self._sub
        return self.whitened(linv[at], self.model.to_targets(changes, at), self._sub_root_counts)

    def decrement(self, theta: np.ndarray) -> float:
        """The Newton decrement gᵀH⁻¹g (twice the ℓ a scoring step would still gain)."""
        grad, step = newton_step(self, theta)
        return float(grad @ step)


def scoring(objective: WhittleObjective, theta0: np.ndarray, tol: float, max_iter: int,
            body: int = 0, near: bool = False) -> OptimizeResult:
    """Scoring by scipy's trust-region method (the Fisher information as the Hessian) until
    :func:`converged`; ``fun`` inf when θ0 gives no finite ℓ. From a start ``near`` the optimum
    (the last window's, a fit's own to go on from, the fit's for the calibration's posterior),
    :func:`_line_scoring` steps first, the trust region going on from where it stops short."""
    def stop_when_converged(intermediate_result: OptimizeResult) -> None:
        if converged(objective, intermediate_result.x, tol, body):
            raise StopIteration

    value = objective.fun(theta0)
    if not np.isfinite(value):
        return OptimizeResult(x=theta0, fun=math.inf, nit=0)
    if near:  # it says whether θ converged: no second test
        theta0, value, walked, done = _line_scoring(objective, theta0, value, tol, max_iter, body)
    else:
        walked, done = 0, converged(objective, theta0, tol, body)
    if done or walked >= max_iter:
        return OptimizeResult(x=theta0, fun=value, nit=walked, success=done)
    res = minimize(objective.fun, theta0, jac=objective.jac, hess=objective.hess, method="trust-exact",
                   callback=stop_when_converged, options={"gtol": 1e-12, "maxiter": max_iter - walked})
    res.nit += walked
    return res


def _line_scoring(objective: WhittleObjective, theta: np.ndarray, value: float, tol: float,
                  max_iter: int, body: int) -> tuple[np.ndarray, float, int, bool]:
    """(θ, ℓ, steps, whether :func:`converged`) of scoring steps with a backtracking line search,
    until converged or a step finds no descent.

    A start from the last window's optimum is within a step or two of the body's (the Fisher
    information models ℓ well there), but a noise floor's log may not be: the floors are a
    small share of an urban window's power and swing within their wide std, the scoring step
    taking a floor towards zero by tens in its log. A trust region spends its radius on that
    log, and the body crawls with it (7-8 iterations a window, measured). Here a floor falls
    as far as its step says, up to :data:`_FLOOR_FALL` (ℓ is flat below a floor's share of
    1e-6: the step's size there costs nothing), rises by at most :data:`_FLOOR_RISE` (ℓ's
    curvature in the log changes sign as the floor overtakes the signal), and the other
    parameters take the step that is best given the floors' (the quadratic model minimised
    with those held)."""
    noise = np.arange(theta.size)[objective.model.noise_slice]
    steps = 0
    while steps < max_iter:
        if converged(objective, theta, tol, body):
            return theta, value, steps, True
        grad, newton = newton_step(objective, theta)
        step, hess = -newton, objective.hess(theta)
        held = noise[(step[noise] > _FLOOR_RISE) | (step[noise] < -_FLOOR_FALL)]
        if held.size:
            free = np.setdiff1d(np.arange(theta.size), held)
            step[held] = np.clip(step[held], -_FLOOR_FALL, _FLOOR_RISE)
            given = grad[free] + hess[np.ix_(free, held)] @ step[held]
            step[free] = -np.linalg.solve(hess[np.ix_(free, free)], given)
        for t in _BACKTRACKS:
            trial = objective.fun(theta + t * step)
            if trial <= value + 1e-4 * t * float(grad @ step):  # Armijo's sufficient decrease
                theta, value, steps = theta + t * step, trial, steps + 1
                break
        else:
            return theta, value, steps, False  # tested above, at this θ
    return theta, value, steps, converged(objective, theta, tol, body)


def converged(objective: WhittleObjective, theta: np.ndarray, tol: float, body: int = 0) -> bool:
    """The Newton decrement ``gᵀH⁻¹g`` below ``tol`` (ℓ within half of it of the optimum), or,
    given the ``body`` leading parameters the fit is for, their part of it below ``tol`` while
    the whole is below :data:`_NUISANCE_DECREMENT`.

    Their part is ``δ_bᵀ ((H⁻¹)_bb)⁻¹ δ_b`` with the Newton step ``δ = H⁻¹g``: the decrement of
    the likelihood profiled over the nuisances, i.e. the body's remaining step in its own std,
    squared. A noise floor on its way to zero moves the whole decrement without end (its log's
    step stays the trust radius while ℓ gains ever less) but not the body: on urban windows a
    third of the iterations were spent so (131 against 88 on 42 warm updates of ``udds``)."""
    grad, step = newton_step(objective, theta)
    whole = float(grad @ step)
    if whole < tol:
        return True
    if not body or whole >= _NUISANCE_DECREMENT:
        return False
    part = step[:body]
    return float(part @ np.linalg.solve(np.linalg.inv(objective.hess(theta))[:body, :body], part)) < tol


def newton_step(objective: WhittleObjective, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(∇ℓ, the scoring step ``H⁻¹ ∇ℓ``) at θ."""
    grad = objective.jac(theta)
    return grad, np.linalg.solve(objective.hess(theta), grad)


def ridged(m: np.ndarray) -> np.ndarray:
    """``m`` plus a ridge of 1e-10 of its largest diagonal entry (flat directions stay still)."""
    return m + 1e-10 * np.max(np.abs(np.diag(m))) * np.eye(m.shape[0])
