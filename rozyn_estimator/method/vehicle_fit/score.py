"""The covariance of the full car's Whittle score under its model (:func:`score_covariance`),
for the published covariance's sandwich ``F⁻¹ Cov(∇ℓ) F⁻¹``.

The tapered window's neighbouring DFT ordinates are correlated: ``C_kk' = E[d_k d_k'ᴴ] =
Σ_j ŵ_j ŵ*_(j+δ) S(f_(k-j))`` (``δ = k' - k``). The score of the fit to group means,
``∇_i ℓ = Σ_g c_g tr(A_ig (Ī_g - S_g))`` with ``A_ig = S_g⁻¹ ∂_i S_g S_g⁻¹``, is a sum over
the bins ``Σ_k tr(A_i,g(k) (I_k - S_g(k)))``, whose covariance (Isserlis' theorem for complex
Gaussian DFT coefficients) is ``Σ_(k,k') Re tr(A_ik C_kk' A_jk' C_k'k)``. Untapered it is the
Fisher information; tapered it holds what the taper correlates. For k×k matrices: the sum over
frequency by the midpoint rule (its summand, model quantities only, is smooth in frequency),
over every lag the window reaches (the far lags' small products add up on short windows).

Why not the Fisher information times the taper's variance factor ``mean(w⁴)/mean(w²)²``
(Dahlhaus), as before: that factor holds where S is smooth and of full rank. The road drives
the four corners through two tracks, so S is nearly of rank 2, and the information in its
small directions is what the taper's smoothing fills with the neighbours' power: measured
on 100 roads (Gaussian ISO A, 100 km/h, 10 % noise), the mass's std so published was 1.22
times its spread; with this sum 1.07, and within 4 % for the other four.
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.method.likelihood.score import lag_covariances, lag_partners, midpoint_bins
from rozyn_estimator.method.likelihood.spectra import Spectra
from rozyn_estimator.method.vehicle_fit.grid import apply, lagrange_matrix
from rozyn_estimator.method.vehicle_fit.stacks import mul
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective

_STEP_HZ = 0.2  # the midpoint rule's spacing (measured against 0.1 Hz: the std within 0.3 %
# at 120 s and 4 % at 30 s; 0.1 Hz would double the work)


def fine_spectrum(objective: WhittleObjective, theta: np.ndarray, spectra: Spectra, reach: int) -> np.ndarray:
    """S (K + 2 reach, k, k) itself (not the periodogram's expectation) at the window's bins
    in the band and ``reach`` bins beyond each of its edges: interpolated from the model's
    nodes as the fit's S is (:mod:`.grid`; the few bins beyond the nodes, a tenth of a hertz
    at most, by the end nodes' polynomials)."""
    df = spectra.fs_hz / spectra.n_samples
    freq = spectra.freq_hz[0] + df * np.arange(-reach, spectra.freq_hz.size + reach)
    return spectrum_itself(objective, theta, freq)


def spectrum_itself(objective: WhittleObjective, theta: np.ndarray, freq_hz: np.ndarray) -> np.ndarray:
    """S (F, k, k) itself, not the periodogram's expectation (no taper's or groups' smoothing),
    at ``freq_hz``: interpolated from the model's nodes as the fit's S is, or evaluated there
    when the model has no grid (nearly noise-free data)."""
    model = objective.model
    if model.grid_hz <= 0:  # beyond the band S is held at its edge's (the road shape's polynomials
        # would run off there; a short window's taper reaches far, even past 0 Hz)
        f = np.clip(freq_hz, model.freq_hz.min(), model.freq_hz.max())
        return model.regrid(f, 0.0, 0.0).spectrum(theta, derivatives=False)[0]
    first_node_hz = model.omega[0] / (2.0 * np.pi)
    return apply(lagrange_matrix((freq_hz - first_node_hz) / model.grid_hz, model.n_freq),
                 objective.node_spectrum(theta))


def score_covariance(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray,
                     spectra: Spectra) -> np.ndarray:
    """(q, q) ``combos Cov(∇ℓ) combosᵀ`` at θ (module docstring); ``combos`` (q, n_params).
    In single precision (a covariance needs no more; twice as fast). (Each pair of bins is
    summed from both ends: the sum over ``δ ≥ 0`` only, doubled, is the same in exact
    arithmetic, but by the midpoint rule 3 % off the mass's std.)"""
    w_hat = spectra.window_dft
    reach = (w_hat.size - 1) // 2
    S, _ = objective.factored(theta)
    A = objective.score_kernels(theta, combos).astype(np.complex64)  # (q, groups, k, k)
    group = np.repeat(np.arange(S.shape[0]), objective.counts.astype(int))  # each bin's group
    K = group.size
    starts, counts, bins = midpoint_bins(K, int(_STEP_HZ * spectra.n_samples / spectra.fs_hz))
    lags, C = lag_covariances(fine_spectrum(objective, theta, spectra, reach), w_hat, bins)
    C = C.astype(np.complex64)  # (n_δ, kc, k, k)
    partner, weight = lag_partners(starts, counts, bins, lags, K)
    q = combos.shape[0]
    left = mul(A[:, group[bins]][:, None], C[None])  # (q, n_δ, kc, k, k): A_k C_kk'
    # tr(A_k C A_k' Cᴴ) = Σ left ⊙ (A_k' Cᴴ)ᵀ, and (A_k' Cᴴ)ᵀ = conj(C A_k') for Hermitian A
    right = np.conj(mul(C[None], A[:, group[partner]])) * weight.astype(np.float32)[None, :, :, None, None]
    out = (left.reshape(q, -1) @ right.reshape(q, -1).T).real.astype(float)
    return 0.5 * (out + out.T)


def sandwich_ratio(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray, model_cov: np.ndarray,
                   spectra: Spectra) -> np.ndarray:
    """(q, q) the sandwich ``combos Cov(∇ℓ) combosᵀ`` (``combos = jac F⁻¹``) over the model's
    std, ``Σ_ij / √(V_ii V_jj)`` with ``V = jac F⁻¹ jacᵀ`` = ``model_cov`` (its diagonal: each
    parameter's variance factor; dimensionless, so that a warm update can keep it while θ
    barely moves). The model's own correlation when the window is untapered (the sandwich
    is then ``V``)."""
    scale = np.sqrt(np.diag(model_cov))
    if spectra.window_dft.size == 1:
        return model_cov / np.outer(scale, scale)
    return score_covariance(objective, theta, combos, spectra) / np.outer(scale, scale)
