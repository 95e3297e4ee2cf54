"""The covariance of the fitted (m, I, lf): the sandwich (:func:`sandwich_covariance`) and
the score's variance measured from the data's time blocks (:func:`_block_variances`).

Covariance: the sandwich ``H⁻¹ J H⁻¹`` mapped to (m, I, lf), with ``H`` the Fisher
information (``covariance="expected"``, free) or the observed information (the Hessian of
ℓ by forward differences of the analytic gradient, ``"observed"``), and ``J`` the
covariance of the score under the fitted model: with no taper and both cross-spectra that
is the Fisher information itself; it adds what the taper correlates (neighbouring
ordinates) and, for the auto-spectra fit, the channels' correlation that fit ignores. A
noise floor run to zero (noise-free data) is held fixed. That ``J`` assumes a stationary
road; on a road whose roughness changes along the way (the Laplace road) the estimate
varies more. So the score's variance is also measured from the data: the score is a
quadratic form of the samples, split over ~12 s time blocks, whose spread (batch means,
the road intensity's drift regressed out) estimates it whatever the road; the published
``J`` is the mean of the model's and the blocks' (``block_weight``, see :func:`sandwich_covariance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from scipy import fft as sfft
from scipy import sparse
from scipy.signal import windows

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.model import HalfCarSpectrum
from rozyn_estimator.method.likelihood.objective import WhittleObjective
from rozyn_estimator.method.likelihood.score import SandwichRatio

NOISE_AT_ZERO = 1e-5  # a noise floor below this share of its channel's band power is zero
_INCOHERENCE_AT_ZERO = 1e-6


class CovarianceError(Exception):
    """The information at the optimum gives no covariance (the fit fails)."""


def sandwich_covariance(
    objective: WhittleObjective, model: HalfCarSpectrum, theta: np.ndarray, cfg: LikelihoodConfig,
    accel: np.ndarray, previous: SandwichRatio | None = None, context: Any = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], SandwichRatio]:
    """(3, 3) covariance of (m, I, lf) from the data's information at the optimum, the factors
    the time blocks applied to the model sandwich's variances, each prior's part, and the
    model sandwich's ratio to the inverse information (``previous``'s, the last window's,
    where it holds for ``context`` and the free parameters: :class:`SandwichRatio`).

    With priors (the calibrated values' tolerances) the posterior's covariance is
    ``H⁻¹ (J + P) H⁻¹``: the data's part ``H⁻¹ J H⁻¹`` (returned) plus, for each parameter
    ``j`` with a prior, ``c_j c_jᵀ`` with ``c_j = B_j √p_j`` (``B = d(m, I, lf)/dθ H⁻¹``):
    what that value's tolerance still contributes after the data's calibration, by name.

    The score's variance along (m, I, lf) is the weighted mean of two estimates,
    ``(1 - ω) J_model + ω J_blocks`` (``ω = cfg.block_weight``), applied to the sandwich as
    a factor per parameter (``cov ← D cov D``, ``D = diag(√factor)``: the correlations stay).
    ``J_model`` is exact for a stationary Gaussian road and has no sampling noise; the
    blocks' (:func:`_block_variances`) is unbiased on any road, the non-stationary ones
    included, but with 8-10 blocks per window it has only 6-8 degrees of freedom.
    Used alone it would make the intervals Student-t-like (under-covering everywhere);
    ``ω = 1/2`` counts the model as much as the blocks: on stationary roads the published
    variance stays unbiased with half that noise, and a non-stationary road's excess is
    carried half way. A compromise by construction, not a fit to any seeds.
    """
    info = objective.observed_information(theta) if cfg.covariance == "observed" else objective.fisher(theta)
    keep = kept(objective, model, theta, info)
    inv = inverse_information(info[np.ix_(keep, keep)])
    # Sandwich H⁻¹ J H⁻¹, projected on (m, I, lf) first: B = d(m, I, lf)/dθ H⁻¹.
    jac = model.physical_jacobian(theta)[:, keep]
    combos = np.zeros((3, theta.size))
    combos[:, keep] = jac @ inv
    scale = np.sqrt(np.diag(jac @ inv @ jac.T))  # the inverse information's std
    ratio = _model_ratio(objective, theta, combos, scale, (context, keep.tobytes()), previous)
    cov = ratio.ratio * np.outer(scale, scale)
    factors = np.ones(3)
    if cfg.block_weight > 0:
        blocks = _block_variances(objective, theta, combos, accel, cfg.block_s, cfg.taper)
        if blocks is not None and np.all(np.diag(cov) > 0):
            factors = 1.0 + cfg.block_weight * (blocks / np.diag(cov) - 1.0)
            scale = np.sqrt(factors)
            cov = scale[:, None] * cov * scale[None, :]
    parts = {}
    if objective.prior is not None:  # the prior's share of the posterior's information
        for j in np.flatnonzero(objective.prior.precision):
            parts[model.names[j]] = combos[:, j] * math.sqrt(objective.prior.precision[j])
    return cov, factors, parts, ratio


def _model_ratio(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray, scale: np.ndarray,
                 context: Any, previous: SandwichRatio | None) -> SandwichRatio:
    """``combos J combosᵀ`` (J the score's covariance under the model) over the inverse
    information's std ``scale`` (3,), or ``previous`` where it holds."""
    n = objective.spectra.n_samples
    if previous is not None and previous.holds(theta, n, context):
        return previous
    cov = objective.score_covariance(theta, combos)
    return SandwichRatio(0.5 * (cov + cov.T) / np.outer(scale, scale), theta.copy(), n, 3, context)


def kept(
    objective: WhittleObjective, model: HalfCarSpectrum, theta: np.ndarray, info: np.ndarray
) -> np.ndarray:
    """(n_params,) the parameters the covariance (and the budget) treats as free."""
    # A noise floor far below its channel's power sits at its boundary (zero): the data
    # hold no information on it, so the fit is conditioned on it.
    keep = np.ones(theta.size, dtype=bool)
    keep[4:6] = np.exp(theta[4:6]) > NOISE_AT_ZERO * objective.band_power
    if "ln_incoherence" in model.index:
        # Likewise the incoherent share when the data do not resolve it (noise dominates):
        # near its boundary the information's curvature misstates the other parameters'.
        k = model.index["ln_incoherence"]
        keep[k] = math.exp(theta[k]) > _INCOHERENCE_AT_ZERO
        if keep[k]:
            sub = info[np.ix_(keep, keep)]
            at = int(np.sum(keep[:k]))
            with np.errstate(all="ignore"):
                keep[k] = bool(np.linalg.pinv(sub)[at, at] < 1.0)  # std of ln(share) < 1
    return keep


def inverse_information(info: np.ndarray) -> np.ndarray:
    """The inverse of a positive-definite information matrix; CovarianceError otherwise.

    Judged and inverted scaled to a unit diagonal: the parameters' scales differ by many
    orders (nearly noise-free data pin the inertia to 1e-8 while a calibrated value stays
    at its prior's few per cent), which alone is no reason to refuse the matrix.
    """
    try:
        d = np.sqrt(np.diag(info))
        if not (np.all(np.isfinite(d)) and np.all(d > 0)):
            raise CovarianceError("likelihood fit: the information matrix is not positive definite")
        scaled = info / np.outer(d, d)
        eig = np.linalg.eigvalsh(scaled)
        if not (np.all(np.isfinite(eig)) and eig.min() > 1e-12 * eig.max()):
            raise CovarianceError("likelihood fit: the information matrix is not positive definite")
        return np.linalg.inv(scaled) / np.outer(d, d)
    except np.linalg.LinAlgError:
        raise CovarianceError("likelihood fit: singular information matrix") from None


_MIN_BLOCKS = 6  # fewer time blocks than this: too few for a variance (the model's J alone)


def _block_variances(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray,
                     accel: np.ndarray, block_s: float, taper: float) -> np.ndarray | None:
    """Variances of ``combos ∇ℓ`` from the score's time blocks, or None (too few blocks).

    Why: the model's J assumes a stationary road. A road whose roughness changes along
    the way (the Laplace road: its intensity jumps every 100 m) makes the estimate vary
    more than that (conditionally on the road's envelope, and through the envelope's own
    smearing of the spectrum), and no stationary model can say by how much. The score
    itself can: ``Σ_k tr(A_k I_k)`` with ``A_k = S⁻¹ (combos ∂S) S⁻¹`` is a quadratic form of
    the (band-limited, tapered) samples, ``Σ_t ψ(t)`` with ``ψ(t) = ỹ_t · ẽ_t / (2 fs)``,
    ``ẽ`` the samples filtered by ``A`` (Parseval). Summed over time blocks ``G_b`` it is a
    sum of nearly independent terms whose spread estimates its variance whatever the
    road (batch means: robust to heteroscedastic, non-stationary data). For the efficient
    directions ``combos = d(m, I, lf)/dθ H⁻¹`` (road intensity and noise floors profiled
    out) a block's expectation is zero whatever its local road intensity:
    ``Σ_k tr(A_k S_road,k) = Σ_k tr(A_k N) = 0``.

    Three details make it work:

    - Blocks of ``block_s`` with raised-cosine edges as long as a block (a smooth
      partition of unity): ``ψ`` is local only beyond the filter's span; a sharp edge
      cuts through pairs of samples whose terms cancel only together (sharp 20 s blocks
      overstate the variance 3-10x).
    - The drift term: the response lags the road, so where the road's intensity ``a²``
      changes, ``ψ``'s local mean is ``c ∂a²/∂t`` (zero in total, but a block picks up
      ``c`` times the change of ``a²`` between its edges, far above its noise on a
      Laplace road). It is regressed out on ``D_b = -Σ_t v_b'(t) P(t)``, ``P`` the samples'
      local power (1 s moving average), and costs one degree of freedom.
    - The estimate at θ̂: the blocks' sum is zero (the fit's own score), which costs
      another degree of freedom: ``Var = B / (B - 2) Σ_b G_b²``.

    With ``B`` = 8-10 blocks (100-120 s windows) the estimate has only 6-8 degrees of
    freedom (±50-60 % on a variance): see :func:`sandwich_covariance` for how it is combined with
    the model's J. Blocks much shorter than ``block_s`` = 12 s overstate the variance even
    on Gaussian roads (the edges still cut the score's filter: 2x at 5 s, +10-40 % at
    10 s at 30-70 km/h); longer ones leave too few.
    """
    spectra = objective.spectra
    n, fs = spectra.n_samples, spectra.fs_hz
    if spectra.dft is None or int(n / fs // block_s) < _MIN_BLOCKS or accel.shape[0] != n:
        return None
    return series_block_variances(_score_series(objective, theta, combos), accel, fs, block_s, taper)


def series_block_variances(psi: np.ndarray, accel: np.ndarray, fs: float, block_s: float,
                           taper: float) -> np.ndarray | None:
    """The variances of a score's data terms ``ψ`` (q, n) from its time blocks, for any number
    of channels (:func:`_block_variances` for why and how); None when there are too few blocks."""
    n = psi.shape[1]
    n_blocks = int(n / fs // block_s)
    if n_blocks < _MIN_BLOCKS or accel.shape[0] != n:
        return None
    blocks = _partition(n, n_blocks, taper)
    share = blocks.share
    G = blocks.weights @ psi.T  # (B, q)
    G -= share[:, None] * G.sum(axis=0)
    y = accel - accel.mean(axis=0)
    power = _moving_average(np.einsum("ta,ta->t", y, y), max(1, round(fs)))
    drift = -(blocks.slopes @ power)
    drift -= share * drift.sum()
    dof = n_blocks - 1
    if drift @ drift > 0:
        G -= np.outer(drift, (drift @ G) / (drift @ drift))
        dof -= 1
    return n_blocks / dof * np.einsum("bq,bq->q", G, G)


def _score_series(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray) -> np.ndarray:
    """(q, n) ψ(t): the score's data term ``Σ_k tr(A_k I_k)`` along each of ``combos`` as a
    sum over the samples, ``A_k = S⁻¹ (combos ∂S) S⁻¹`` (restricted as the fit's).

    ``ψ(t) = ỹ_t · ẽ_t / (2 fs)`` with ``ỹ`` the tapered samples and ``ẽ`` the samples filtered
    by ``A``, both band-limited (inverse FFTs of ``d_k`` and ``A_k d_k`` on the band): by
    Parseval ``Σ_t ψ(t) = Re Σ_k d_kᴴ A_k d_k / (n fs)``.
    """
    spectra = objective.spectra
    n, fs, d = spectra.n_samples, spectra.fs_hz, spectra.dft
    if d is None:
        raise ValueError("the score's time series needs the window's DFT (Spectra.dft)")
    A = objective.score_weights(theta, combos)  # (q, k, 2, 2)
    k0, k = spectra.first_bin, d.shape[0]
    full = np.zeros((1 + combos.shape[0], n // 2 + 1, 2), dtype=complex)  # ỹ and the filtered ẽ
    full[0, k0: k0 + k] = d
    full[1:, k0: k0 + k] = matrices_times_vectors(A, d)
    series = sfft.irfft(full, n=n, axis=1)
    return channel_products(series[0], series[1:]) / (2.0 * fs)


def matrices_times_vectors(A: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(q, k, c) ``A_qk d_k`` for matrices ``A`` (q, k, c, c) and vectors ``d`` (k, c): a sum
    over the c columns (einsum's generic loop is 5x slower for 2 or 4 channels)."""
    return sum(A[..., b] * d[None, :, b, None] for b in range(d.shape[1]))


def channel_products(y: np.ndarray, e: np.ndarray) -> np.ndarray:
    """(q, n) ``Σ_a y_ta e_qta`` for ``y`` (n, c) and ``e`` (q, n, c): a sum over the c channels."""
    return sum(y[:, a] * e[..., a] for a in range(y.shape[1]))


@dataclass(frozen=True)
class _Partition:
    """A smooth partition of unity over the samples: B blocks, each rising and falling over a
    block's length with raised cosines, so each sample belongs to two neighbouring blocks
    with weights ``cos²`` and ``sin²`` of its place between their centres (to the first and
    the last alone beyond their centres). Sparse (two weights per sample), so that a block
    sum ``Σ_t v_b(t) x(t)`` of every block is one product."""

    weights: sparse.csr_array  # (B, n) each block's weight v_b(t)
    slopes: sparse.csr_array  # (B, n) its slope along the samples
    share: np.ndarray  # (B,) each block's share of the tapered window's power (the score's expectation)


@lru_cache(maxsize=8)
def _partition(n: int, n_blocks: int, taper: float) -> _Partition:
    """The blocks of :class:`_Partition` (cached: consecutive windows share it)."""
    length = n / n_blocks
    t = (np.arange(n) + 0.5) / length - 0.5  # block centres at 0, 1, ..
    lower = np.clip(np.floor(t).astype(int), 0, n_blocks - 1)
    inside = (t >= 0) & (t <= n_blocks - 1)
    f = np.where(inside, t - lower, 0.0)  # place between the lower block's centre and the next's
    rows = np.r_[lower, np.minimum(lower + 1, n_blocks - 1)]
    cols = np.r_[np.arange(n), np.arange(n)]

    def matrix(lower_values: np.ndarray, upper_values: np.ndarray) -> sparse.csr_array:
        out = sparse.csr_array((np.r_[lower_values, upper_values], (rows, cols)), shape=(n_blocks, n))
        out.sum_duplicates()
        for a in (out.data, out.indices, out.indptr):
            a.flags.writeable = False  # shared by the cache
        return out

    weights = matrix(np.cos(0.5 * np.pi * f) ** 2, np.sin(0.5 * np.pi * f) ** 2)
    slope = 0.5 * np.pi / length * np.sin(np.pi * f) * inside
    w2 = windows.tukey(n, taper) ** 2 if taper > 0 else np.ones(n)
    share = weights @ (w2 / w2.sum())
    share.flags.writeable = False
    return _Partition(weights, matrix(-slope, slope), share)


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average over ``width`` samples (shorter at the ends)."""
    c = np.r_[0.0, np.cumsum(x)]
    lo = np.clip(np.arange(x.size) - width // 2, 0, x.size)
    hi = np.clip(lo + width, 0, x.size)
    return (c[hi] - c[lo]) / (hi - lo)
