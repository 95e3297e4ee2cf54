"""What the covariance of the Whittle score under the model (:mod:`rozyn_estimator.method.vehicle_fit.score`:
the sum ``Σ_(k,k') Re tr(A_ik C_kk' A_jk' C_k'k)`` over the band's pairs of bins, for a tapered
window whose neighbouring DFT ordinates are correlated) is computed with: the lags' covariances
``C_kk'``, the midpoint rule's bins and partners; and the sandwich's ratio a warm update keeps
(:class:`SandwichRatio`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

# The sum over frequency takes one bin in this width (the midpoint rule on a smooth summand:
# measured, within 1e-4 of the covariance at 30-120 s)
BODY_MOVE = 0.01  # a warm update keeps a sandwich's ratio while the body's θ move less ...
NUISANCE_MOVE = 0.1  # ... and the others (road, noise floors, shape, calibrated values) less than this


@dataclass(frozen=True)
class SandwichRatio:
    """The model sandwich's covariance of the estimated parameters over their inverse
    information's std, ``Σ_ij / √(V_ii V_jj)``, and where it was taken: a property of the model
    at θ (the taper's correlations, the fit's weights), not of the data, so that the next
    window's update may keep it (:meth:`holds`) instead of summing the score's covariance again.

    Why the nuisances count too: the ratio moves with the signal-to-noise ratio (measured on
    the half car at 100 km/h, one at a time: +0.5 in a noise floor's log moves the mass's
    ratio by 7-16 %, -0.5 in the road's log by 17 %), and a Laplace road's intensity drifts by
    0.2 in a minute while the body's parameters stay within 0.5 %. Measured over 12 windows
    5 s apart (Gaussian and Laplace roads, 100 km/h): with ``NUISANCE_MOVE`` 0.1, 9-10 of 12
    updates kept the ratio, and where it was recomputed (beyond 0.1) it had moved by at most
    6 % (I's variance), 2 % elsewhere; the sum costs a third of a warm update's uncertainty.
    (0.05 kept only 4 of 12: the noise floors' own estimates move 5-9 % a window.)
    """

    ratio: np.ndarray  # (q, q)
    theta: np.ndarray  # all fitted parameters it was taken at
    n_samples: int  # the window's length
    n_body: int  # θ's leading body parameters (held to BODY_MOVE)
    context: Any = None  # what else it rests on (vehicle, settings, free parameters): equal, or recomputed

    def holds(self, theta: np.ndarray, n_samples: int, context: Any = None) -> bool:
        """This ratio stands for one taken at ``theta`` on a window of ``n_samples``."""
        if n_samples != self.n_samples or theta.shape != self.theta.shape or context != self.context:
            return False
        moved = np.abs(theta - self.theta)
        return bool(np.all(moved[: self.n_body] < BODY_MOVE) and np.all(moved[self.n_body:] < NUISANCE_MOVE))


def lag_covariances(
    S_ext: np.ndarray, w_hat: np.ndarray, bins: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(lags δ, C_(k, k+δ) at the bins ``k`` of ``bins``): (n_δ,), (n_δ, len(bins), k, k)
    (``S_ext``: (bins + 2J, k, k), the band's and J beyond each edge).

    ``C_(k, k+δ) = Σ_j ŵ_j ŵ*_(j+δ) S_ext(k - j + J)``: one matrix product of the window
    products with the shifted spectra, for every lag the window reaches (|δ| ≤ 2J: the
    small window products of the far lags still add up, 9 % of a 20 s window's mass
    variance when lags below 1 % were cut).
    """
    n = w_hat.size  # 2J + 1
    lags = np.arange(-(n - 1), n)
    products = np.zeros((lags.size, n), dtype=complex)  # [δ, j + J] = ŵ_j ŵ*_(j+δ)
    for row, d in enumerate(lags):
        j = np.arange(max(0, -int(d)), min(n, n - int(d)))
        products[row, j] = w_hat[j] * np.conj(w_hat[j + d])
    shifted = S_ext[(n - 1 - np.arange(n))[:, None] + bins[None, :]]  # [j + J, k] = S_ext[J - j + k]
    C = products @ shifted.reshape(n, -1)
    return lags, C.reshape(lags.size, bins.size, *S_ext.shape[1:])


def midpoint_bins(n_bins: int, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The midpoint rule's blocks of ``step`` bins over ``n_bins``: (first bins, sizes, centre bins)."""
    starts = np.arange(0, n_bins, max(1, step))
    counts = np.diff(np.r_[starts, n_bins])
    return starts, counts, starts + (counts - 1) // 2


def lag_partners(starts: np.ndarray, counts: np.ndarray, bins: np.ndarray, lags: np.ndarray,
                 n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """(each centre bin's partner ``k + δ`` per lag, clipped to the band; the bins of each
    block whose partner lies in the band, counted exactly: the band's edges are where the
    summand is not smooth), both (n_δ, blocks)."""
    ends = np.minimum(starts + counts, n_bins - lags[:, None])
    weight = np.maximum(0, ends - np.maximum(starts, -lags[:, None]))
    return np.clip(bins[None, :] + lags[:, None], 0, n_bins - 1), weight


