"""The full car's covariance on roads that are not stationary: the score's time blocks and
the road's intermittency.

The inverse Fisher information assumes a stationary Gaussian road. A road whose roughness
changes along the way (the Laplace road) makes the estimate vary more than that. Two
measures of how much, each blind where the other sees; the published factor on each
parameter's variance is the larger (:func:`variance_factors`):

- **The time blocks** (:func:`block_factors`). As for the half car (:func:`rozyn_estimator.
  method.likelihood.covariance.series_block_variances`, which explains the blocks, their
  smooth edges and the drift term): the score's data term along each parameter's efficient
  direction ``c = d(m, I_xx, I_yy, l_f, y_c)/dθ F⁻¹`` is a sum over the samples,
  ``ψ(t) = ỹ_t · ẽ_t / (2 fs)`` (``ỹ`` the band-limited tapered samples, ``ẽ`` the samples
  filtered by ``A_k = S⁻¹ (c·∂S) S⁻¹``; Parseval), whose spread over time blocks estimates
  its variance on any road. The factor is the weighted mean ``(1 - ω) model + ω blocks``
  (``block_weight``). It sees what a change of roughness does where it happens (the
  response lagging the road) and the mass's, pitch's and CoG's variance (mostly measured
  against the noise floors) rises as it says on a Laplace road.
- **The intermittency** (:func:`intermittency_factors`). A road that is a Gaussian one
  times a slowly varying envelope ``√Y(s)`` (Bogsjö's Laplace road, a road of patches)
  has the score variance ``Σ_k κ tr(A S_r A S_r) + 2 tr(A S_r A N) + tr(A N A N)`` (``S_r``
  the road's part of ``S``, ``N`` the noise floors'), ``κ = E[Y²]/E[Y]²`` of this drive:
  each piece of road counts by its own roughness squared. ``κ`` shows in the samples'
  kurtosis, ``3 κ`` for the road's part of a band-limited signal. The roll inertia draws
  nearly all its information from the road's part (the two tracks' difference), and its
  score's blocks miss the rise (measured: variance 2.1× the model's on ν = 1 at 100 km/h,
  the blocks 1.2-1.6×, ``κ`` 2.0×); the intermittency gives it.

Both are one per parameter, applied to the variances (the correlations stay).
"""

from __future__ import annotations

import numpy as np
from scipy import fft as sfft

from rozyn_estimator.method.full.whittle import FullWhittle
from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.covariance import (
    channel_products,
    matrices_times_vectors,
    series_block_variances,
)
from rozyn_estimator.method.likelihood.spectra import Spectra


def variance_factors(objective: FullWhittle, theta: np.ndarray, combos: np.ndarray, cov: np.ndarray,
                     spectra: Spectra, accel: np.ndarray, noise_share: np.ndarray,
                     cfg: LikelihoodConfig) -> np.ndarray:
    """(q,) the factors on the model's variances ``diag(cov)`` of the ``combos`` (q, n_params)
    directions: the larger of the time blocks' and the intermittency's (module docstring);
    ones when neither can be measured."""
    if spectra.dft is None or not np.all(np.diag(cov) > 0):
        return np.ones(combos.shape[0])
    samples = _band_samples(spectra, spectra.dft[None])[0]
    return np.maximum(block_factors(objective, theta, combos, cov, spectra, accel, cfg, samples),
                      intermittency_factors(objective, theta, combos, samples, noise_share, cfg.taper))


def block_factors(objective: FullWhittle, theta: np.ndarray, combos: np.ndarray, cov: np.ndarray,
                  spectra: Spectra, accel: np.ndarray, cfg: LikelihoodConfig,
                  samples: np.ndarray | None = None) -> np.ndarray:
    """(q,) the time blocks' factors (ones when the window holds too few blocks or
    ``block_weight`` is 0); ``samples`` the band-limited tapered samples if already made."""
    ones = np.ones(combos.shape[0])
    d = spectra.dft
    if cfg.block_weight <= 0 or d is None or not np.all(np.diag(cov) > 0):
        return ones
    A = np.repeat(_score_kernels(objective, theta, combos), objective.counts.astype(int), axis=1)
    filtered = _band_samples(spectra, matrices_times_vectors(A, d))
    y_band = _band_samples(spectra, d[None])[0] if samples is None else samples
    psi = channel_products(y_band, filtered) / (2.0 * spectra.fs_hz)
    blocks = series_block_variances(psi, accel, spectra.fs_hz, cfg.block_s, cfg.taper)
    if blocks is None:
        return ones
    return 1.0 + cfg.block_weight * (blocks / np.diag(cov) - 1.0)


def intermittency_factors(objective: FullWhittle, theta: np.ndarray, combos: np.ndarray,
                          samples: np.ndarray, noise_share: np.ndarray, taper: float) -> np.ndarray:
    """(q,) ``1 + (κ - 1) ρ`` per direction: ``κ`` the road's intermittency
    (:func:`road_intermittency`), ``ρ`` the share of the direction's score variance that is
    the road's alone, ``Σ tr(A S_r A S_r) / Σ tr(A S A S)`` (module docstring)."""
    kappa = road_intermittency(samples, noise_share, taper)
    if kappa <= 1.0:
        return np.ones(combos.shape[0])
    S, dS, _ = objective.at(theta)
    road = dS[objective.model.index["ln_road"]]
    A = _score_kernels(objective, theta, combos)
    counts = objective.counts
    ar, a_all = A @ road[None], A @ S[None]
    road_only = np.einsum("qkab,qkba,k->q", ar, ar, counts).real
    total = np.einsum("qkab,qkba,k->q", a_all, a_all, counts).real
    share = np.clip(road_only / np.where(total > 0, total, np.inf), 0.0, 1.0)
    return 1.0 + (kappa - 1.0) * share


def road_intermittency(samples: np.ndarray, noise_share: np.ndarray, taper: float) -> float:
    """``κ = E[Y²]/E[Y]²`` of the road's envelope over this window (1 for a Gaussian road),
    from the kurtosis of the band-limited samples ``(n, k)`` where the taper is flat.

    Per channel ``x = √Y r + e`` (road part ``r``, power share ``1 - η``; noise ``e``,
    share ``η`` = ``noise_share``): ``E x⁴ / (E x²)² = 3 (κ (1 - η)² + 2 η (1 - η) + η²)``.
    The channels' values are pooled with weights ``(1 - η)²`` (a channel mostly noise says
    little); never below 1 (a mixture's ``κ`` cannot be)."""
    n = samples.shape[0]
    edge = int(np.ceil(0.5 * taper * n)) + 1
    x = samples[edge: n - edge] if n - 2 * edge > 100 else samples
    power = np.mean(x * x, axis=0)
    if not np.all(power > 0):
        return 1.0
    m4 = np.mean(x**4, axis=0) / power**2
    eta = np.clip(np.asarray(noise_share, dtype=float), 0.0, 1.0)
    road = 1.0 - eta
    weights = road**2
    if weights.sum() <= 0:
        return 1.0
    per_channel = (m4 / 3.0 - 2.0 * eta * road - eta**2) / np.where(weights > 0, weights, 1.0)
    return float(max(1.0, np.sum(weights * per_channel) / weights.sum()))


def _score_kernels(objective: FullWhittle, theta: np.ndarray, combos: np.ndarray) -> np.ndarray:
    """``A = S⁻¹ (c·∂S) S⁻¹`` per direction and frequency group, (q, groups, k, k)."""
    _, dS, linv = objective.at(theta)
    inv = linv.conj().swapaxes(1, 2) @ linv
    return inv @ np.tensordot(combos, dS, axes=1) @ inv


def _band_samples(spectra: Spectra, band_dft: np.ndarray) -> np.ndarray:
    """(m, n, k) the time series of ``m`` band-limited DFTs (m, bins, k) placed on the
    window's band (the other bins zero)."""
    n, k0 = spectra.n_samples, spectra.first_bin
    full = np.zeros((band_dft.shape[0], n // 2 + 1, band_dft.shape[2]), dtype=complex)
    full[:, k0: k0 + band_dft.shape[1]] = band_dft
    return sfft.irfft(full, n=n, axis=1)
