"""The Whittle objective: :class:`WhittleObjective` (ℓ(θ), its gradient, the Fisher and
observed information, the optimiser's Hessian and the score's covariance) and its helpers
on stacks of 2x2 Hermitian matrices (:func:`inv2`, the curvatures, the ridge).

The negative Whittle log-likelihood of the window's periodogram matrices ``I_k`` at the
Fourier frequencies ``f_k`` of the band

    ℓ(θ) = Σ_k log det S_k + tr(S_k⁻¹ I_k)

with ``S_k`` the half car's spectral matrix at θ (:mod:`rozyn_estimator.method.likelihood.model`).
Its Hessian, as the optimiser sees it, is the Fisher information far from the optimum and,
near it, the Fisher information with the exact rows of ``σ²`` and the noise floors (their
second derivatives are known in closed form); the Newton decrement ``gᵀF⁻¹g`` says how
close the optimum is. ``spectra="auto"`` uses the auto-spectra only (for comparison).

A :class:`Prior` adds ``½ Σ_j p_j (θ_j - μ_j)²`` to ℓ for the parameters that carry one
(the sensors' self-calibration: their tolerance is the prior's standard deviation), so ℓ
is then the negative log posterior and its information ``F + diag(p)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.likelihood.grid import map_bins
from rozyn_estimator.method.likelihood.model import HalfCarSpectrum
from rozyn_estimator.method.likelihood.score import SUM_STEP_HZ, covariance_sum
from rozyn_estimator.method.likelihood.spectra import Spectra, band_power

_NEAR = 10.0  # Newton decrement below which the optimiser uses the sharper Hessian


def inv2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(inverse, real determinant) of a stack of 2x2 Hermitian matrices (the inverse is
    meaningless where the determinant is not positive: callers check it)."""
    inv = np.empty_like(S)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # an optimiser's wild step: inf
        det = (S[:, 0, 0] * S[:, 1, 1]).real - np.abs(S[:, 0, 1]) ** 2
        inv[:, 0, 0], inv[:, 1, 1] = S[:, 1, 1] / det, S[:, 0, 0] / det
        inv[:, 0, 1], inv[:, 1, 0] = -S[:, 0, 1] / det, -S[:, 1, 0] / det
    return inv, det


def mul2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Products of stacked 2x2 matrices (..., 2, 2), broadcast: numpy's ``@`` loops over the
    stack one tiny matrix at a time, this is the four entries' vectorised sums (2-3x faster)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    a00, a01, a10, a11 = a[..., 0, 0], a[..., 0, 1], a[..., 1, 0], a[..., 1, 1]
    b00, b01, b10, b11 = b[..., 0, 0], b[..., 0, 1], b[..., 1, 0], b[..., 1, 1]
    out[..., 0, 0] = a00 * b00 + a01 * b10
    out[..., 0, 1] = a00 * b01 + a01 * b11
    out[..., 1, 0] = a10 * b00 + a11 * b10
    out[..., 1, 1] = a10 * b01 + a11 * b11
    return out


def cholesky2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(l11, l21, l22) of ``S = L Lᴴ``, ``L = [[l11, 0], [l21, l22]]``, for a stack of positive
    definite 2x2 Hermitian matrices; ``l22² = det S / S11`` with det as :func:`inv2` computes
    it (positive wherever ℓ is finite: the textbook ``S22 - |l21|²`` can round below zero)."""
    l11 = np.sqrt(S[:, 0, 0].real)
    l22 = np.sqrt(((S[:, 0, 0] * S[:, 1, 1]).real - np.abs(S[:, 0, 1]) ** 2) / S[:, 0, 0].real)
    return l11, S[:, 1, 0] / l11, l22


def whitened(S: np.ndarray, dS: np.ndarray) -> np.ndarray:
    """(p, 4k) real rows ``R_i`` with ``R_i · R_j = Σ_k tr(S⁻¹ ∂_i S S⁻¹ ∂_j S)``, for
    positive definite ``S`` (k, 2, 2) and Hermitian ``dS`` (p, k, 2, 2).

    With ``S = L Lᴴ`` (Cholesky) the trace is ``tr(W_i W_j)``, ``W = L⁻¹ ∂S L⁻ᴴ``
    Hermitian: the real inner product of each ``W``'s four real numbers (diagonal, and
    the off-diagonal's real and imaginary parts weighted √2), a quarter of the work of
    the complex products. The Fisher information is ``R Rᵀ``: the fit's most frequent
    large product.
    """
    l11, l21, l22 = cholesky2(S)
    g = l21 / l11
    a, b, d = dS[:, :, 0, 0].real, dS[:, :, 1, 0], dS[:, :, 1, 1].real  # ∂S's three numbers
    # W = L⁻¹ ∂S L⁻ᴴ with L⁻¹ = [[1/l11, 0], [-l21/(l11 l22), 1/l22]]; per-bin factors once
    p, k = a.shape
    out = np.empty((p, 4, k))
    root2 = math.sqrt(2.0)
    np.multiply(a, 1.0 / S[:, 0, 0].real, out=out[:, 0])  # w11
    w21 = (b - g * a) * (root2 / (l11 * l22))
    out[:, 1] = (d - 2.0 * (np.conj(g) * b).real + np.abs(g) ** 2 * a) * (1.0 / l22**2)  # w22
    out[:, 2], out[:, 3] = w21.real, w21.imag  # √2 w21
    return out.reshape(p, -1)


def _exact_rows(
    inv: np.ndarray, dS_rows: np.ndarray, M: np.ndarray, dS: np.ndarray, fisher_rows: np.ndarray,
    to_nodes: Callable[[np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """Rows of the Hessian of ℓ without the terms of ∂²S, for the parameters whose
    derivatives at the bins are ``dS_rows`` (r, k, 2, 2): with ``V_i = S⁻¹ ∂_i S`` and
    ``M = S⁻¹ I``, ``Σ_k tr(V_i V_j M) + tr(V_j V_i M) - tr(V_i V_j)`` (its expectation, at
    ``M = 1``, is the Fisher information, whose rows ``fisher_rows`` are).

    By the trace's cyclic property the first two terms are ``tr(Z_i ∂_j S)`` with
    ``Z_i = (M V_i + V_i M) S⁻¹``: only the rows' ``V_i`` are formed, and the sum over the
    parameters ``j`` is one matrix product (as the gradient's) — also with ``dS`` at the
    evaluation grid's nodes, ``Z`` taken there by ``to_nodes`` (the map's adjoint).
    """
    V = mul2(inv, dS_rows)
    Z = mul2(mul2(M, V) + mul2(V, M), inv)  # (r, k, 2, 2)
    if to_nodes is not None:
        Z = to_nodes(Z)
    p = dS.shape[0]
    both = (Z.transpose(0, 1, 3, 2).reshape(Z.shape[0], -1) @ dS.reshape(p, -1).T).real
    return both - fisher_rows


@dataclass(frozen=True)
class Prior:
    """Independent Gaussian priors on some of θ: mean ``μ`` and precision ``p = 1/σ²`` per
    parameter (``p = 0``: none)."""

    mean: np.ndarray
    precision: np.ndarray

    def penalty(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """(½ Σ p (θ - μ)², its gradient)."""
        d = theta - self.mean
        return 0.5 * float(np.sum(self.precision * d * d)), self.precision * d


def _ridged(m: np.ndarray) -> np.ndarray:
    """``m`` plus a ridge of 1e-10 of its largest diagonal entry (flat directions stay still)."""
    return m + 1e-10 * np.max(np.abs(np.diag(m))) * np.eye(m.shape[0])


class WhittleObjective:
    """ℓ(θ), its gradient and the Fisher information, with the last evaluation cached."""

    def __init__(self, model: HalfCarSpectrum, spectra: Spectra, spectra_kind: str = "cross",
                 prior: Prior | None = None) -> None:
        self.model = model
        self.prior = prior
        self.auto = spectra_kind == "auto"
        self.periodogram = self.restrict(spectra.periodogram)
        self.band_power = band_power(spectra)
        self.window_dft = spectra.window_dft
        self.spectra = spectra
        self._key: bytes | None = None
        self._value: tuple[float, np.ndarray] | None = None
        self._parts: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._model: tuple[np.ndarray, np.ndarray] | None = None  # (S, dS) at the cached θ, restricted
        self._fisher: np.ndarray | None = None
        self._hess: np.ndarray | None = None
        self._rows: np.ndarray | None = None
        self._weights: tuple[bytes, np.ndarray] | None = None  # (θ and combos, score_weights there)
        # The fit's iterations (``fast``): derivatives at the evaluation grid's nodes, the
        # gradient exact through the map's adjoint, the Fisher information from the bins at
        # the centre of every ``step`` (the midpoint rule, each weighted by the bins it
        # stands for): an optimiser's Hessian; the covariance evaluates at every bin again.
        self.fast = False
        step = model.grid_step
        starts = np.arange(0, model.n_freq, step)
        counts = np.diff(np.r_[starts, model.n_freq])
        self._sampled = starts + (counts - 1) // 2
        self._sample_map = model.reduction.rows(tuple(self._sampled.tolist()))
        self._sample_root_weight = np.tile(np.sqrt(counts), 4)
        self._nodes: tuple[np.ndarray, np.ndarray] | None = None  # (S at the bins, dS at the nodes)

    def restrict(self, m: np.ndarray) -> np.ndarray:
        """Stacked 2x2 matrices (..., 2, 2) as the fit sees them: unchanged, or for the
        auto-spectra fit their diagonal part only."""
        if not self.auto:
            return m
        out = np.zeros_like(m)
        out[..., 0, 0], out[..., 1, 1] = m[..., 0, 0], m[..., 1, 1]
        return out

    def nll(self, S: np.ndarray) -> float:
        """ℓ for a model spectrum ``S`` (k, 2, 2); inf where S is not positive definite."""
        return self._nll(self.restrict(S))[0]

    def _nll(self, S: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """(ℓ, S⁻¹, S⁻¹ I) from the model's S."""
        inv, det = inv2(S)
        if not (np.all(np.isfinite(det)) and np.all(det > 0) and np.all(S[:, 0, 0].real > 0)):
            return math.inf, inv, inv
        SiI = mul2(inv, self.periodogram)
        return float(np.sum(np.log(det)) + np.einsum("kaa->", SiI).real), inv, SiI

    def evaluate(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """(ℓ, ∇ℓ) at θ; ℓ = inf where S is not positive definite."""
        key = np.asarray(theta, dtype=float).tobytes() + bytes([self.fast])
        if key == self._key and self._value is not None:
            return self._value
        if not self.fast:
            S, dS = self.model.spectrum(theta)
            return self.seed(theta, S, dS)
        S_nodes, dS_nodes = self.model.spectrum(theta, smooth=False)
        assert dS_nodes is not None
        S, dS_nodes = self.restrict(self.model.reduction.bins(S_nodes)), self.restrict(dS_nodes)
        value = self._seed(theta, S, dS_nodes, self.model.reduction.adjoint)
        self._key, self._model, self._nodes = key, None, (S, dS_nodes)
        return value

    def seed(self, theta: np.ndarray, S: np.ndarray, dS: np.ndarray) -> tuple[float, np.ndarray]:
        """(ℓ, ∇ℓ) at θ from the model's S and dS/dθ computed elsewhere (cached as :meth:`evaluate`'s)."""
        S, dS = self.restrict(S), self.restrict(dS)
        value = self._seed(theta, S, dS)
        self._key, self._model = np.asarray(theta, dtype=float).tobytes() + bytes([False]), (S, dS)
        return value

    def _seed(self, theta: np.ndarray, S: np.ndarray, dS: np.ndarray,
              to_nodes: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[float, np.ndarray]:
        """(ℓ, ∇ℓ) from S at the bins and dS at the bins (or at the nodes, ``to_nodes`` the
        map's adjoint); resets what was cached of the previous θ."""
        nll, inv, SiI = self._nll(S)
        p = self.model.n_params
        if not math.isfinite(nll):
            value, self._parts = (math.inf, np.zeros(p)), None
        else:
            W = inv - mul2(SiI, inv)  # S⁻¹ - S⁻¹ I S⁻¹
            if to_nodes is not None:
                W = to_nodes(W)
            grad = (dS.reshape(p, -1) @ W.transpose(0, 2, 1).ravel()).real  # Σ_k tr(∂S W)
            if self.prior is not None:
                penalty, slope = self.prior.penalty(np.asarray(theta, dtype=float))
                nll, grad = nll + penalty, grad + slope
            value, self._parts = (nll, grad), (inv, S, SiI)
        self._value, self._fisher, self._hess, self._rows = value, None, None, None
        return value

    def model_at(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(S, dS/dθ) at θ as the fit sees them (restricted), from the last evaluation if it was at θ."""
        if self.fast:
            raise ValueError("the model at the bins is not evaluated in the fit's fast iterations")
        self.evaluate(theta)
        assert self._model is not None
        return self._model

    def fun(self, theta: np.ndarray) -> float:
        return self.evaluate(theta)[0]

    def jac(self, theta: np.ndarray) -> np.ndarray:
        return self.evaluate(theta)[1]

    def whitened_rows(self, theta: np.ndarray) -> np.ndarray:
        """:func:`whitened` rows of the model at θ (the Fisher information is ``R Rᵀ``), cached."""
        self.evaluate(theta)
        if self._rows is None:
            if self._nodes is not None and self.fast:
                S, dS = self._nodes
                sampled = self.restrict(map_bins(self._sample_map, dS))
                self._rows = whitened(S[self._sampled], sampled) * self._sample_root_weight
            elif self._model is not None:
                self._rows = whitened(*self._model)
            else:
                raise ValueError("no model at θ")
        return self._rows

    def fisher(self, theta: np.ndarray) -> np.ndarray:
        """The Fisher information at θ (the expected Hessian of ℓ, the prior's included)."""
        self.evaluate(theta)
        if self._fisher is None:
            if self._parts is None:
                self._fisher = np.eye(self.model.n_params)
            else:
                rows = self.whitened_rows(theta)
                fisher = rows @ rows.T
                if self.prior is not None:
                    fisher = fisher + np.diag(self.prior.precision)
                self._fisher = fisher
        return self._fisher

    def _hessian(self, theta: np.ndarray) -> np.ndarray:
        """The Fisher information with the exact rows of the parameters that scale a part of S."""
        fisher = self.fisher(theta)
        _, grad = self.evaluate(theta)
        if self._hess is None:
            if self._parts is None:
                self._hess = fisher
            else:
                # The rows of the parameters that scale a part of S (road intensity, noise
                # floors) are exact: their second derivatives are ∂²S/∂θ_i∂θ_j = ∂S/∂θ_j
                # (the road intensity with every parameter of the road part, each noise
                # floor with itself), whose terms are the gradient's. There the Fisher
                # information can be far off (noise floors are seen at few frequencies);
                # elsewhere the transfer functions' second derivatives matter and it is good.
                data = fisher if self.prior is None else fisher - np.diag(self.prior.precision)
                if self.prior is not None:  # the data's gradient: the prior's slope is not S's
                    grad = grad - self.prior.penalty(np.asarray(theta, dtype=float))[1]
                inv, S, SiI = self._parts
                exact = _exact_rows(inv, self._scale_rows(theta, S), SiI, self._derivatives(), data[3:6],
                                    self.model.reduction.adjoint if self.fast else None)
                road = [j for j in range(self.model.n_params) if j not in (4, 5)]
                exact[0, road] += grad[road]  # and, by symmetry, the column of the road intensity
                exact[1, 4] += grad[4]
                exact[2, 5] += grad[5]
                if self.prior is not None:
                    exact = exact + np.diag(self.prior.precision)[3:6]
                hess = fisher.copy()
                hess[3:6], hess[:, 3:6] = exact, exact.T
                self._hess = hess
        return self._hess

    def _derivatives(self) -> np.ndarray:
        """dS/dθ of the cached evaluation: at the bins, or at the nodes in the fast iterations."""
        cached = self._nodes if self.fast else self._model
        assert cached is not None
        return cached[1]

    def _scale_rows(self, theta: np.ndarray, S: np.ndarray) -> np.ndarray:
        """dS/dθ at the bins of the road intensity and the noise floors (3, k, 2, 2): the road
        part of S, and each floor's diagonal entry."""
        noise = np.exp(theta[4:6])
        out = np.zeros((3, *S.shape), dtype=S.dtype)
        out[0] = S
        out[0, :, 0, 0] -= noise[0] + self.model.min_noise_psd[0]
        out[0, :, 1, 1] -= noise[1] + self.model.min_noise_psd[1]
        out[1, :, 0, 0], out[2, :, 1, 1] = noise[0], noise[1]
        return out

    def decrement(self, theta: np.ndarray, free: np.ndarray | None = None) -> float:
        """Newton decrement gᵀF⁻¹g: twice the ℓ a scoring step would still gain (over the
        ``free`` parameters only, when given: the others held where they are)."""
        _, grad = self.evaluate(theta)
        info = _ridged(self.fisher(theta))
        if free is not None:
            grad, info = grad[free], info[np.ix_(free, free)]
        return float(grad @ np.linalg.solve(info, grad))

    def hess(self, theta: np.ndarray) -> np.ndarray:
        """The optimiser's Hessian, with a tiny ridge so that a direction the data say
        nothing about (a noise floor run to zero) stays still: far from the optimum the
        Fisher information (scoring, robust); near it (decrement below ``_NEAR``) with the
        exact rows of the road intensity and noise floors (fast final convergence)."""
        return _ridged(self.fisher(theta) if self.decrement(theta) > _NEAR else self._hessian(theta))

    def observed_information(self, theta: np.ndarray, step: float = 1e-5) -> np.ndarray:
        """Hessian of ℓ at θ by forward differences of the analytic gradient."""
        g0 = self.jac(theta).copy()
        h = np.array([(self.jac(theta + step * e) - g0) / step for e in np.eye(theta.size)]).T
        return 0.5 * (h + h.T)

    def score_weights(self, theta: np.ndarray, combos: np.ndarray) -> np.ndarray:
        """(q, k, 2, 2) ``A_k = S⁻¹ (combos ∂S) S⁻¹`` at θ: the score along ``combos`` is
        ``Σ_k tr(A_k (S_k - I_k))`` (cached for the last θ and combos: the covariance's two
        estimates of the score's variance, the model's and the time blocks', share them)."""
        key = np.asarray(theta, dtype=float).tobytes() + np.asarray(combos, dtype=float).tobytes()
        if self._weights is None or self._weights[0] != key:
            S, dS = self.model_at(theta)
            inv = inv2(S)[0]
            self._weights = key, mul2(mul2(inv, np.tensordot(combos, dS, axes=1)), inv)
        return self._weights[1]

    def score_covariance(self, theta: np.ndarray, combos: np.ndarray) -> np.ndarray:
        """``combos Cov(∇ℓ) combosᵀ`` under the full (cross-spectral) model at θ.

        ``Cov(g_i, g_j) = Σ_(k,k') Re tr(A_ik C_kk' A_jk' C_k'k)`` with ``A_i = S⁻¹ ∂_i S S⁻¹``
        of the fitted likelihood (diagonal for the auto-spectra fit) and
        ``C_kk' = E[d_k d_k'ᴴ] = Σ_j ŵ_j ŵ*_(j+k'-k) S(f_(k-j))`` (Isserlis' theorem for
        complex Gaussian DFT coefficients). Untapered and cross-spectral it is the Fisher
        information; it adds what the auto-spectra fit ignores (the channels'
        correlation) and what a taper correlates (neighbouring ordinates).

        Args:
            combos: (q, n_params) linear combinations of the score wanted.
        """
        model = self.model
        S_ext = model.fine_spectrum(theta)
        A = self.score_weights(theta, combos)
        c = np.abs(self.window_dft) ** 2
        centre = (c.size - 1) // 2
        w_hat = self.window_dft[centre - model.half: centre + model.half + 1]  # as the model's kernel
        step = max(1, int(SUM_STEP_HZ * self.spectra.n_samples / self.spectra.fs_hz))
        return covariance_sum(A, S_ext, w_hat, step)
