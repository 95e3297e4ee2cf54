"""The full car's covariance on a road that is not stationary: the road's intermittency
(:func:`variance_factors`).

The inverse Fisher information assumes a stationary Gaussian road. A road that is a Gaussian
one times a slowly varying envelope ``√Y(s)`` (Bogsjö's Laplace road, a road of patches)
makes the estimate vary more: each piece of road counts by its own roughness squared, so
the score's variance along a direction is ``Σ_k κ tr(A S_r A S_r) + 2 tr(A S_r A N) +
tr(A N A N)`` (``A = S⁻¹ (c·∂S) S⁻¹``, ``c = d(m, I_xx, I_yy, l_f, y_c)/dθ F⁻¹`` the
parameter's efficient direction; ``S_r`` the road's part of ``S``, ``N`` the noise
floors'), ``κ = E[Y²]/E[Y]²`` of this drive. ``κ`` shows in the samples' kurtosis, ``3 κ``
for the road's part of a band-limited signal (:func:`road_intermittency`). Each variance is
raised by ``1 + (κ - 1) ρ``, ``ρ`` the share of the direction's score variance that is the
road's alone (:func:`intermittency_factors`).

``S_r`` there is the road's part itself (:func:`road_itself`), not the periodogram's
expectation that the fit models (``S + m₂ S''/2``, the taper's and the groups' smoothing).
The road drives four corners through two tracks, so ``S_r`` is nearly of rank 2, and the
mass, the pitch inertia and the CoG draw their information mostly from the directions it
lacks, where the smoothing puts some road power from the neighbouring frequencies. That
leaked power does not vary with the envelope as the road's own does (measured, 300 roads
on the Laplace road at 100 km/h, two vehicles: the mass's variance needed a factor 0.90 and
1.03; counting the leaked power as the road's gave 1.37 and 1.46 on average, the road's own
1.01 and 1.03). The roll inertia draws nearly all its information from the road's own part
(the tracks' difference): its variance needed 2.0 times the model's, and gets 1.8.

Not the score's time blocks (the score, a quadratic form of the samples, split over ~12 s
blocks and its variance measured from their spread, as the half car's covariance once had it):
the full car's took the larger of the blocks' factor and this one before. Measured on 300 roads in each of
the ten acceptance cases (Gaussian ISO A at 30-100 km/h and the Laplace road, two vehicles),
the blocks' factors on the Gaussian roads, where 1 is right, averaged 1.07 for the mass,
1.08 for the pitch inertia, 1.14 for l_f and 0.91 for the roll inertia; the published std
over the estimates' rms error was 1.09 on average and 20 of the 150 coverages were outside
90-98 %; with the intermittency alone 1.01 and 4 of 150 (a right std misses about 7: 100 roads
are few).

The factors are one per parameter, applied to the variances (the correlations stay). On a
varying drive each stretch of the window at its own speed has its own spectrum; the factors
are the larger of this module's and the stretches' (:mod:`.stretches`, the road's
intermittency multiplying each stretch's road part).
"""

from __future__ import annotations

import numpy as np
from scipy import fft as sfft

from rozyn_estimator.method.likelihood.spectra import Spectra
from rozyn_estimator.method.vehicle_fit.score import spectrum_itself
from rozyn_estimator.method.vehicle_fit.stretches import Stretches, drive_stretches, pairs, stretched_factors
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective


def variance_factors(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray, spectra: Spectra,
                     noise_share: np.ndarray, taper: float) -> np.ndarray:
    """(q,) the factors on the model's variances of the ``combos`` (q, n_params) directions
    for the window's intermittency (module docstring) and, on a varying drive, its stretches
    at different speeds (:func:`drive_stretches`); ones when the samples are not at hand (a
    window without its DFT)."""
    if spectra.dft is None:
        return np.ones(combos.shape[0])
    samples = _band_samples(spectra, spectra.dft[None])[0]
    model = objective.model
    stretches = None
    if model.mixture is not None and model.sample_weights is not None and \
            np.size(model.speed_mps) == spectra.n_samples:
        stretches = drive_stretches(model.vehicle.wheelbase_m, np.asarray(model.speed_mps), spectra.fs_hz,
                                    model.sample_weights)
    return intermittency_factors(objective, theta, combos, samples, noise_share, taper, stretches)


def intermittency_factors(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray,
                          samples: np.ndarray, noise_share: np.ndarray, taper: float,
                          stretches: Stretches | None = None) -> np.ndarray:
    """(q,) per direction: ``1 + (κ - 1) ρ``, ``κ`` the road's intermittency
    (:func:`road_intermittency`), ``ρ`` the share of the direction's score variance that is
    the road's alone, ``Σ tr(A S_r A S_r) / Σ tr(A S A S)`` (module docstring). On a varying
    drive's ``stretches`` the larger of that and each stretch's own spectrum's
    (:func:`.stretches.stretched_factors`): two measures, each blind where the other sees.
    The stretches see how each parameter's information moves with the speed (the roll's at
    low speed); the samples' kurtosis, which the speed's envelope and the masked zeros raise
    for every parameter alike, also sees what the model of stretches lacks: the square gates'
    edges, which cut the body's response mid-swing. Measured on urban windows (12 roads, 144
    windows, exact vehicle), the larger covered the truth 98 / 92 / 98 / 97 / 92 % (m, I_xx,
    I_yy, l_f, y_c) with four corners, where the kurtosis alone gave 98 / 88 / 98 / 97 / 90 and
    the stretches alone 97 / 92 / 94 / 92 / 92; one IMU 98 / 91 / 88 / 91 / 89 % (the kurtosis
    alone 98 / 87 / 88 / 91 / 86)."""
    m4 = channel_kurtosis(samples, taper)
    if m4 is None:
        return np.ones(combos.shape[0])
    at, counts = objective.sampled_frequencies()  # the sums are smooth in frequency, as the Fisher's
    A = objective.score_kernels(theta, combos)[:, at]
    S = objective.factored(theta)[0][at]
    total = pairs(A, S, S, counts)
    kappa = _pooled(*channel_intermittency(m4, noise_share))
    steady = np.ones(combos.shape[0])
    if kappa > 1.0:
        road = road_itself(objective, theta, at)
        share = np.clip(pairs(A, road, road, counts) / np.where(total > 0, total, np.inf), 0.0, 1.0)
        steady = 1.0 + (kappa - 1.0) * share
    if stretches is None:
        return steady
    return np.maximum(steady, stretched_factors(objective, theta, A, total, m4, stretches, at, counts))


def road_itself(objective: WhittleObjective, theta: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
    """(K, k, k) S's road part itself at the fit's frequencies (or those ``at``), not the periodogram's
    expectation: without the taper's and the groups' smoothing (``m₂ S''/2``), which puts
    some road power where the road itself has none (module docstring: why that part is no
    envelope's). The noise floors are white: S less its diagonal floors.

    The half car's one track is the exception: the power the smoothing moves into the
    direction its rank-one road lacks is that track's own at the neighbouring frequencies, and
    varies with the envelope as the road does. Its road part is the expectation's (Laplace
    road, 100 km/h, 100 s, 40 roads each: the mass' error over its std had an rms of 1.32 on a
    second vehicle with the road itself, 1.13 with this; 1.02 and 0.91 on Table 5-1's)."""
    model = objective.model
    at = np.arange(model.freq_hz.size) if at is None else at
    S = spectrum_itself(objective, theta, model.freq_hz[at]) if model.rolls else \
        objective.factored(theta)[0][at]
    return S - np.eye(model.k) * (np.exp(theta[model.noise_slice]) + model.min_noise_psd)


def road_intermittency(samples: np.ndarray, noise_share: np.ndarray, taper: float) -> float:
    """``κ = E[Y²]/E[Y]²`` of the road's envelope over this window (1 for a Gaussian road),
    from the kurtosis of the band-limited samples ``(n, k)`` where the taper is flat
    (:func:`channel_intermittency`, pooled; never below 1: a mixture's ``κ`` cannot be)."""
    m4 = channel_kurtosis(samples, taper)
    return 1.0 if m4 is None else _pooled(*channel_intermittency(m4, noise_share))


def channel_kurtosis(samples: np.ndarray, taper: float) -> np.ndarray | None:
    """(k,) each channel's ``E x⁴ / (E x²)²`` where the taper is flat (None: a silent channel)."""
    n = samples.shape[0]
    edge = int(np.ceil(0.5 * taper * n)) + 1
    x = samples[edge: n - edge] if n - 2 * edge > 100 else samples
    squares = x * x  # and their squares: x**4 calls pow per element, 15 times slower
    power = np.mean(squares, axis=0)
    if not np.all(power > 0):
        return None
    return np.asarray(np.mean(squares * squares, axis=0) / power**2)


def channel_intermittency(m4: np.ndarray, noise_share: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(each channel's ``κ``, its weight in the pool) from its kurtosis ``m4``.

    Per channel ``x = √Y r + e`` (road part ``r``, power share ``1 - η``; noise ``e``,
    share ``η`` = ``noise_share``): ``E x⁴ / (E x²)² = 3 (κ (1 - η)² + 2 η (1 - η) + η²)``.
    The channels' values are pooled with weights ``(1 - η)²`` (a channel mostly noise says
    little)."""
    eta = np.clip(np.asarray(noise_share, dtype=float), 0.0, 1.0)
    road = 1.0 - eta
    weights = road**2
    per_channel = (m4 / 3.0 - 2.0 * eta * road - eta**2) / np.where(weights > 0, weights, 1.0)
    return per_channel, weights


def _pooled(per_channel: np.ndarray, weights: np.ndarray) -> float:
    if weights.sum() <= 0:
        return 1.0
    return float(max(1.0, np.sum(weights * per_channel) / weights.sum()))


def _band_samples(spectra: Spectra, band_dft: np.ndarray) -> np.ndarray:
    """(m, n, k) the time series of ``m`` band-limited DFTs (m, bins, k) placed on the
    window's band (the other bins zero)."""
    n, k0 = spectra.n_samples, spectra.first_bin
    full = np.zeros((band_dft.shape[0], n // 2 + 1, band_dft.shape[2]), dtype=complex)
    full[:, k0: k0 + band_dft.shape[1]] = band_dft
    return sfft.irfft(full, n=n, axis=1)
