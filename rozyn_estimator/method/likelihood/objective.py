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
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.likelihood.model import HalfCarSpectrum
from rozyn_estimator.method.likelihood.spectra import Spectra, band_power

_NEAR = 10.0  # Newton decrement below which the optimiser uses the sharper Hessian


def inv2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(inverse, real determinant) of a stack of 2x2 Hermitian matrices (the inverse is
    meaningless where the determinant is not positive: callers check it)."""
    det = (S[:, 0, 0] * S[:, 1, 1]).real - np.abs(S[:, 0, 1]) ** 2
    inv = np.empty_like(S)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv[:, 0, 0], inv[:, 1, 1] = S[:, 1, 1] / det, S[:, 0, 0] / det
        inv[:, 0, 1], inv[:, 1, 0] = -S[:, 0, 1] / det, -S[:, 1, 0] / det
    return inv, det


def whitened(S: np.ndarray, dS: np.ndarray) -> np.ndarray:
    """(p, 4k) real rows ``R_i`` with ``R_i · R_j = Σ_k tr(S⁻¹ ∂_i S S⁻¹ ∂_j S)``, for
    positive definite ``S`` (k, 2, 2) and Hermitian ``dS`` (p, k, 2, 2).

    With ``S = L Lᴴ`` (Cholesky) the trace is ``tr(W_i W_j)``, ``W = L⁻¹ ∂S L⁻ᴴ``
    Hermitian: the real inner product of each ``W``'s four real numbers (diagonal, and
    the off-diagonal's real and imaginary parts weighted √2), a quarter of the work of
    the complex products. The Fisher information is ``R Rᵀ``: the fit's most frequent
    large product.
    """
    l11 = np.sqrt(S[:, 0, 0].real)
    l21 = S[:, 1, 0] / l11
    l22 = np.sqrt(S[:, 1, 1].real - np.abs(l21) ** 2)
    a, b, d = dS[:, :, 0, 0].real, dS[:, :, 1, 0], dS[:, :, 1, 1].real  # ∂S's three numbers
    # W = L⁻¹ ∂S L⁻ᴴ with L⁻¹ = [[1/l11, 0], [-l21/(l11 l22), 1/l22]]
    w11 = a / l11**2
    w21 = (b - l21 * a / l11) / (l11 * l22)
    w22 = (d - 2.0 * (np.conj(l21) * b).real / l11 + np.abs(l21) ** 2 * a / l11**2) / l22**2
    p = dS.shape[0]
    root2 = math.sqrt(2.0)
    return np.concatenate([w11, w22, root2 * w21.real, root2 * w21.imag], axis=1).reshape(p, -1)


def _v(inv: np.ndarray, dS: np.ndarray) -> np.ndarray:
    """The ``V_i = S⁻¹ ∂_i S``, (p, k, 2, 2)."""
    return inv[None, :, :, :1] * dS[:, :, None, 0] + inv[None, :, :, 1:] * dS[:, :, None, 1]


def _exact_rows(V: np.ndarray, SiI: np.ndarray, fisher: np.ndarray, rows: slice) -> np.ndarray:
    """Rows ``rows`` of the Hessian of ℓ without the terms of ∂²S: with ``M = S⁻¹ I``,
    ``Σ_k tr(V_i V_j M) + tr(V_j V_i M) - tr(V_i V_j)`` (its expectation, at ``M = 1``, is
    the Fisher information)."""
    p = V.shape[0]
    VM = V[..., :1] * SiI[None, :, None, 0] + V[..., 1:] * SiI[None, :, None, 1]
    flat, flat_m = V.reshape(p, -1), VM.transpose(0, 1, 3, 2).reshape(p, -1)
    B_rows = (flat[rows] @ flat_m.T).real  # B[rows, :]
    B_cols = (flat @ flat_m[rows].T).real  # B[:, rows]
    return B_rows + B_cols.T - fisher[rows]


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
        per = spectra.periodogram
        self.periodogram = self.restrict(per)
        self.band_power = band_power(spectra)
        self.window_dft = spectra.window_dft
        self.spectra = spectra
        self._key: bytes | None = None
        self._value: tuple[float, np.ndarray] | None = None
        self._parts: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._model: tuple[np.ndarray, np.ndarray] | None = None  # (S, dS) at the cached θ, restricted
        self._fisher: np.ndarray | None = None
        self._hess: np.ndarray | None = None

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
        SiI = inv @ self.periodogram
        return float(np.sum(np.log(det)) + np.einsum("kaa->", SiI).real), inv, SiI

    def evaluate(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """(ℓ, ∇ℓ) at θ; ℓ = inf where S is not positive definite."""
        key = np.asarray(theta, dtype=float).tobytes()
        if key == self._key and self._value is not None:
            return self._value
        S, dS = self.model.spectrum(theta)
        return self.seed(theta, S, dS)

    def seed(self, theta: np.ndarray, S: np.ndarray, dS: np.ndarray) -> tuple[float, np.ndarray]:
        """(ℓ, ∇ℓ) at θ from the model's S and dS/dθ computed elsewhere (cached as :meth:`evaluate`'s)."""
        key = np.asarray(theta, dtype=float).tobytes()
        S, dS = self.restrict(S), self.restrict(dS)
        self._model = (S, dS)
        nll, inv, SiI = self._nll(S)
        p = self.model.n_params
        if not math.isfinite(nll):
            value, self._parts = (math.inf, np.zeros(p)), None
        else:
            W = inv - SiI @ inv  # S⁻¹ - S⁻¹ I S⁻¹
            grad = (dS.reshape(p, -1) @ W.transpose(0, 2, 1).ravel()).real  # Σ_k tr(∂S W)
            if self.prior is not None:
                penalty, slope = self.prior.penalty(np.asarray(theta, dtype=float))
                nll, grad = nll + penalty, grad + slope
            value, self._parts = (nll, grad), (inv, dS, SiI)
        self._key, self._value, self._fisher, self._hess = key, value, None, None
        return value

    def model_at(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(S, dS/dθ) at θ as the fit sees them (restricted), from the last evaluation if it was at θ."""
        self.evaluate(theta)
        assert self._model is not None
        return self._model

    def fun(self, theta: np.ndarray) -> float:
        return self.evaluate(theta)[0]

    def jac(self, theta: np.ndarray) -> np.ndarray:
        return self.evaluate(theta)[1]

    def fisher(self, theta: np.ndarray) -> np.ndarray:
        """The Fisher information at θ (the expected Hessian of ℓ, the prior's included)."""
        self.evaluate(theta)
        if self._fisher is None:
            if self._parts is None or self._model is None:
                self._fisher = np.eye(self.model.n_params)
            else:
                rows = whitened(self._model[0], self._parts[1])
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
                exact = _exact_rows(_v(*self._parts[:2]), self._parts[2], data, slice(3, 6))
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

    def decrement(self, theta: np.ndarray) -> float:
        """Newton decrement gᵀF⁻¹g: twice the ℓ a scoring step would still gain."""
        _, grad = self.evaluate(theta)
        return float(grad @ np.linalg.solve(_ridged(self.fisher(theta)), grad))

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

    def score_covariance(self, theta: np.ndarray, combos: np.ndarray) -> np.ndarray:
        """``combos Cov(∇ℓ) combosᵀ`` under the full (cross-spectral) model at θ.

        ``Cov(g_i, g_j) = Σ_(k,k') Re tr(A_ik C_kk' A_jk' C_k'k)`` with ``A_i = S⁻¹ ∂_i S S⁻¹``
        of the fitted likelihood (diagonal for the auto-spectra fit) and
        ``C_kk' = E[d_k d_k'ᴴ] = Σ_j ŵ_j ŵ*_(j+k'-k) S(f_(k-j))`` (Isserlis' theorem for
        complex Gaussian DFT coefficients). Untapered and cross-spectral it is the Fisher
        information; it adds what the auto-spectra fit ignores (the channels' correlation)
        and what a taper correlates (neighbouring ordinates).

        Args:
            combos: (q, n_params) linear combinations of the score wanted.
        """
        model = self.model
        S_ext, _ = model.spectrum(theta, derivatives=False, smooth=False)
        S, dS = self.model_at(theta)
        inv = inv2(S)[0]
        dS = np.tensordot(combos, dS, axes=1)  # (q, k, 2, 2)
        A = inv[None] @ dS @ inv[None]
        half, k = model.half, model.n_freq
        c = np.abs(self.window_dft) ** 2
        centre = (c.size - 1) // 2
        w_hat = self.window_dft[centre - half: centre + half + 1]  # as the model's kernel
        q = A.shape[0]
        out = np.zeros((q, q))
        # Offsets whose window products are all below 1 % add < 1e-4 of J: skipped.
        reach = [d for d in range(2 * half + 1)
                 if np.sum(np.abs(w_hat[: w_hat.size - d] * w_hat[d:])) >= 0.01]
        top = max(reach) if reach else 0
        for delta in range(-top, top + 1):
            # C_(k, k+δ) for the band's k, from S on the extended grid (index k - j + J)
            C = sum(w_hat[j + half] * np.conj(w_hat[j + delta + half]) * S_ext[half - j: half - j + k]
                    for j in range(max(-half, -half - delta), min(half, half - delta) + 1))
            lo, hi = max(0, -delta), min(k, k - delta)
            X = A[:, lo:hi] @ C[None, lo:hi]
            Y = A[:, lo + delta: hi + delta] @ C[None, lo:hi].conj().transpose(0, 1, 3, 2)
            out += (X.reshape(q, -1) @ Y.transpose(0, 1, 3, 2).reshape(q, -1).T).real
        return 0.5 * (out + out.T)
