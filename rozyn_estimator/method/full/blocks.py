"""The full car's covariance on roads that are not stationary: the score's time blocks.

The inverse Fisher information assumes a stationary Gaussian road. A road whose roughness
changes along the way (the Laplace road) makes the estimate vary more than that; the score
itself can say by how much. As for the half car (:func:`rozyn_estimator.method.likelihood.
covariance.series_block_variances`, which explains the blocks, their smooth edges and the
drift term): the score's data term along each parameter's efficient direction
``c = d(m, I_xx, I_yy, l_f, y_c)/dθ F⁻¹`` is a sum over the samples, ``ψ(t) = ỹ_t · ẽ_t / (2 fs)``
(``ỹ`` the band-limited tapered samples, ``ẽ`` the samples filtered by
``A_k = S⁻¹ (c·∂S) S⁻¹``; Parseval), whose spread over time blocks estimates its variance
on any road. The published variance is the weighted mean ``(1 - ω) model + ω blocks``
(``block_weight``), applied as a factor per parameter (the correlations stay).
"""

from __future__ import annotations

import numpy as np
from scipy import fft as sfft

from rozyn_estimator.method.full.whittle import FullWhittle
from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.covariance import series_block_variances
from rozyn_estimator.method.likelihood.spectra import Spectra


def block_factors(objective: FullWhittle, theta: np.ndarray, combos: np.ndarray, cov: np.ndarray,
                  spectra: Spectra, accel: np.ndarray, cfg: LikelihoodConfig) -> np.ndarray:
    """(q,) the factors on the model's variances ``diag(cov)`` of the ``combos`` (q, n_params)
    directions (ones when the window holds too few blocks or ``block_weight`` is 0)."""
    ones = np.ones(combos.shape[0])
    d = spectra.dft
    if cfg.block_weight <= 0 or d is None or not np.all(np.diag(cov) > 0):
        return ones
    _, dS, linv = objective.at(theta)
    inv = linv.conj().swapaxes(1, 2) @ linv
    A = inv @ np.tensordot(combos, dS, axes=1) @ inv  # (q, groups, k, k)
    A = np.repeat(A, objective.counts.astype(int), axis=1)  # each group's model at its bins
    n, k0 = spectra.n_samples, spectra.first_bin
    full = np.zeros((1 + combos.shape[0], n // 2 + 1, d.shape[1]), dtype=complex)
    full[0, k0: k0 + d.shape[0]] = d
    full[1:, k0: k0 + d.shape[0]] = np.einsum("qkab,kb->qka", A, d)
    series = sfft.irfft(full, n=n, axis=1)
    psi = np.einsum("ta,qta->qt", series[0], series[1:]) / (2.0 * spectra.fs_hz)
    blocks = series_block_variances(psi, accel, spectra.fs_hz, cfg.block_s, cfg.taper)
    if blocks is None:
        return ones
    return 1.0 + cfg.block_weight * (blocks / np.diag(cov) - 1.0)
