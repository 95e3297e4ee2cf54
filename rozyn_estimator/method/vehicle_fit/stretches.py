"""A varying drive's stretches: how much more the full car's estimate varies when the window's
road comes at several speeds (:func:`stretched_factors`).

The likelihood of a varying drive models the window's spectrum as the mixture of its stretches'
local spectra, ``S = Σ_g π_g Ŝ_g`` (``π_g`` each stretch's share of the window's square, the
taper times the stretches' gates, :mod:`~rozyn_estimator.method.likelihood.road_input`). That
is the periodogram's expectation, but not its covariance: neighbouring DFT ordinates are
correlated by the window's changing power, and the score of a direction with kernels ``A = S⁻¹
(c·∂S) S⁻¹`` varies as ``Σ_g ω_g Σ_k tr(A Ŝ_g A Ŝ_g)`` (``ω_g`` the stretch's share of the
window's fourth power; a locally stationary process), not as ``Σ_k tr(A S A S)``. How much more
depends on the direction: the roll inertia and the lateral CoG draw their information from the
tracks' difference, whose power grows at low speed (the tracks' coherence falls with the
spatial frequency ``f / v``), the mass from the heave, whose power falls with the speed. The
samples the model masks (standing, pulling away: their data are zeroed) carry nothing, so a
window masked in part counts the rest for more. Measured on urban windows (the full car, 12
roads, exact vehicle) with one road intermittency factor for every parameter (the samples'
kurtosis, which the speed's envelope raises to about 1.9): the mass's std was 1.19 times the
error's rms, the roll inertia's 0.77 and the lateral CoG's 0.79. :mod:`.intermittency`
publishes the larger of that factor and these.

The road's own intermittency (:mod:`.intermittency`) multiplies each stretch's road part:
the samples' kurtosis is compared with what the stretches' powers alone give
(``E[x⁴]/3 = κ E_u[P²] + 2 E_u[P N] + E_u[N²]``, ``u`` the shares of the window's flat part).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.likelihood.road_input import delay_bins, is_varying
from rozyn_estimator.method.vehicle_fit.grid import apply, lagrange_matrix
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.stacks import herm, mul
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective

GROUPS = 5  # the drive's delay bins in this many stretches of equal time (a group costs ~5 ms)


@dataclass(frozen=True)
class Stretches:
    """A varying drive's samples in groups of nearly the same speed (masked samples in none)."""

    parts: np.ndarray  # (G, bins) bool: each group's delay bins (the mixture's)
    time: np.ndarray  # (G,) its share of the window's square (taper and gates), π
    fourth: np.ndarray  # (G,) its share of the window's fourth power, ω
    flat: np.ndarray  # (G,) its share of the samples where the window is flat (the kurtosis'), u


def drive_stretches(wheelbase_m: float, speed_mps: np.ndarray, fs_hz: float, sample_weights: np.ndarray,
                    groups: int = GROUPS) -> Stretches | None:
    """The window's stretches (None: one speed while driving, or no driving); ``sample_weights``
    (n,) the square of each sample's window (the taper's, times the steady stretches' gates:
    the model's)."""
    if not is_varying(speed_mps):
        return None
    tau, bins = delay_bins(wheelbase_m, speed_mps, fs_hz)
    if tau.size < 2:
        return None
    w2 = np.asarray(sample_weights, dtype=float)
    flat = (w2 >= 1.0 - 1e-9).astype(float)  # neither tapered nor ramped
    driven = bins >= 0

    def shares(weight: np.ndarray) -> np.ndarray:
        return np.bincount(bins[driven], weights=weight[driven], minlength=tau.size) / weight.sum()

    time = shares(w2)
    middle = (np.cumsum(time) - 0.5 * time) / max(time.sum(), 1e-300)
    group = np.minimum((middle * groups).astype(int), groups - 1)
    parts = np.array([group == g for g in range(groups) if np.any(time[group == g] > 0)])
    if parts.shape[0] < 2:
        return None
    fourth, on_flat = shares(w2 * w2), shares(flat)
    return Stretches(parts, parts @ time, parts @ fourth, parts @ on_flat)


def road_parts(objective: WhittleObjective, theta: np.ndarray, parts: np.ndarray,
               at: np.ndarray | None = None) -> np.ndarray:
    """(G, K, k, k) S's road part itself (no taper's smoothing) at the fit's frequencies (or those
    ``at``) from each group of the mixture's delay bins alone, weighted as in the whole (the
    groups sum to it)."""
    model: VehicleSpectrum = objective.model
    assert model.mixture is not None
    _, H, _, _, _ = model.body_motion(theta)
    reads = mul(model.sensing_at(theta), H)
    weight = model.road_weight(theta)[:, None, None]
    scale = float(np.exp(theta[model.index["ln_coherence_scale"]])) if model.rolls else None
    delay, coherence = model.mixture.parts(parts, scale)  # (G, F, 2, 2) each
    if coherence is None:
        inputs = delay
    else:  # the wheels' (F, 4, 4), the groups stacked as frequencies
        inputs = model.road_inputs(coherence.reshape(-1, 2, 2), delay=delay.reshape(-1, 2, 2))
        inputs = inputs.reshape(*delay.shape[:2], 4, 4)
    at_nodes = model.fold(mul(mul(reads, weight * inputs), herm(reads)))
    at = np.arange(model.freq_hz.size) if at is None else at
    if model.grid_hz <= 0:  # S at each frequency: the nodes are the targets, with one beyond each
        targets = at_nodes if at_nodes.shape[1] == model.freq_hz.size else at_nodes[:, 1:-1]  # end to smooth
        return targets[:, at]
    first_node_hz = model.omega[0] / (2.0 * np.pi)
    to_targets = lagrange_matrix((model.freq_hz[at] - first_node_hz) / model.grid_hz, model.n_freq)
    return apply(to_targets, at_nodes)


def pairs(A: np.ndarray, left: np.ndarray, right: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(q,) ``Σ_k c_k Re tr(A_k L_k A_k R_k)`` per direction (``left``, ``right``: (K, k, k))."""
    return traced(mul(A, left[None]), mul(A, right[None]), counts)


def traced(X: np.ndarray, Y: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(..., q) ``Σ_k c_k Re tr(X_k Y_k)`` of stacked products ``X = A L``, ``Y = A R`` (..., q, K,
    k, k), broadcast: each product formed once serves every pair it is in."""
    return np.einsum("...kab,...kba->...k", X, Y).real @ counts


def stretched_factors(objective: WhittleObjective, theta: np.ndarray, A: np.ndarray, total: np.ndarray,
                      kurtosis: np.ndarray, stretches: Stretches, at: np.ndarray | None = None,
                      counts: np.ndarray | None = None) -> np.ndarray:
    """(q,) the factors on the model's variances of the directions whose kernels are ``A``
    (``total`` their model variance ``Σ tr(A S A S)``), from the stretches' own spectra and the
    road's intermittency left in the samples' ``kurtosis`` (k,) (module docstring); at least 1.
    ``A`` and ``total`` are at the frequencies ``at`` (default: all), each standing for ``counts``
    bins (default: the objective's)."""
    model = objective.model
    counts = objective.counts if counts is None else counts
    parts = road_parts(objective, theta, stretches.parts, at)  # (G, K, k, k)
    noise = np.eye(model.k) * (np.exp(theta[model.noise_slice]) + model.min_noise_psd)
    local = parts / stretches.time[:, None, None, None]  # Ŝ_g's road part
    unmasked = float(stretches.time.sum())
    local_noise = noise / unmasked  # the masked samples are zeroed, noise and all
    kappa = _road_kappa(local, local_noise, counts, kurtosis, stretches.flat)
    # A N for a diagonal N scales A's columns; A Ŝ_g once per stretch, and their weighted sum
    # is A times the whole road part (the stretches sum to it)
    a_noise = A * np.diagonal(local_noise)[None, None, None, :]
    a_local = mul(A[None], local[:, None])  # (G, q, K, k, k)
    noise_pairs = traced(a_noise, a_noise, counts)
    each = kappa * traced(a_local, a_local, counts) + 2.0 * traced(a_local, a_noise, counts) + noise_pairs
    varied = stretches.fourth @ each
    a_road = np.tensordot(stretches.time, a_local, axes=1)
    a_all_noise = unmasked * a_noise
    steady = traced(a_road, a_road, counts) + 2.0 * traced(a_road, a_all_noise, counts) + \
        traced(a_all_noise, a_all_noise, counts)
    return np.maximum(1.0, 1.0 + (varied - steady) / np.where(total > 0, total, np.inf))


def _road_kappa(local: np.ndarray, local_noise: np.ndarray, counts: np.ndarray, kurtosis: np.ndarray,
                flat: np.ndarray) -> float:
    """The road's own intermittency: each channel's ``E[x⁴]/3 = κ E_u[P²] + 2 E_u[P] N + E_u[1] N²``
    solved for ``κ`` (``P`` the stretch's road power, ``N`` the noise's), pooled with the road's
    share squared; at least 1."""
    power = np.einsum("gkcc,k->gc", local, counts).real  # (G, k) each stretch's road power
    n = np.einsum("cc->c", local_noise).real * counts.sum()
    mean_x2 = flat @ (power + n)
    road2 = flat @ (power * power)
    if not np.all(road2 > 0) or not np.all(mean_x2 > 0):
        return 1.0
    per_channel = (kurtosis / 3.0 * mean_x2**2 - 2.0 * (flat @ power) * n - flat.sum() * n * n) / road2
    weights = ((flat @ power) / mean_x2) ** 2
    return float(max(1.0, np.sum(weights * per_channel) / weights.sum()))


__all__ = ["GROUPS", "Stretches", "drive_stretches", "pairs", "road_parts", "stretched_factors", "traced"]
