"""What each channel contributes to an estimate: the share of each parameter's information
that would be lost without it.

For the fitted model's Whittle information ``F = Σ_f w_f tr(S⁻¹ ∂S S⁻¹ ∂S)`` (every fitted
parameter's, the nuisances' too) a parameter's variance is ``(J F⁻¹ Jᵀ)_ii``; without
channel ``c`` the same sum runs over ``S`` and ``∂S`` with ``c``'s row and column deleted
(the parameters only ``c`` informs, its noise floor and gain, dropped). The share lost is
``1 - var(all) / var(without c)``: 0 where the others carry everything, 1 where the
parameter cannot be told without ``c``. The shares of several channels need not sum to 1:
the half car's two channels each carry all of it (a channel's own spectrum tells under
0.05 %: the cross-spectrum holds the rest), a full car's IMU's ``gyro_x`` all of the roll's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

SHORT_NAMES = {"mass_kg": "m", "pitch_inertia_kgm2": "I_yy", "cog_from_front_axle_m": "l_f",
               "roll_inertia_kgm2": "I_xx", "cog_lateral_m": "y_c"}
_UNSEEN = 1e-12  # a parameter with less information than this share of its own (all channels) is dropped
_RIDGE = 1e-12  # on the correlation form: a parameter the rest cannot tell has a variance ~1/_RIDGE


def information_lost(S: np.ndarray, dS: np.ndarray, weights: np.ndarray | None,
                     jac: np.ndarray, every: int = 1) -> np.ndarray:
    """(k, q) the share of each of the ``q`` parameters' information lost without each channel.

    Args:
        S: (K, k, k) the fitted spectral matrices.
        dS: (p, K, k, k) their derivatives by the fit's parameters θ.
        weights: (K,) what each frequency counts for (None: 1).
        jac: (q, p) d(parameters)/dθ.
        every: sum over every ``every``-th frequency only (the shares are smooth in frequency:
            every 12th bin gave the half car's to 0.1 % at a tenth of the work, 1-2 ms).
    """
    k, at = S.shape[-1], slice(every // 2, None, every)
    S, dS = S[at], dS[:, at]
    w = np.ones(S.shape[0]) if weights is None else np.asarray(weights, dtype=float).ravel()[at]
    full = _fisher(S, dS, w)
    seen = np.diag(full) > 0
    var_all = _variances(full, jac, seen)
    out = np.ones((k, jac.shape[0]))
    for c in range(k):
        keep = [i for i in range(k) if i != c]
        if not keep:
            continue
        part = _fisher(S[:, keep][:, :, keep], dS[:, :, keep][:, :, :, keep], w)
        told = seen & (np.diag(part) > _UNSEEN * np.where(seen, np.diag(full), 1.0))
        var = _variances(part, jac, told)
        out[c] = np.clip(1.0 - var_all / var, 0.0, 1.0)
    return out


def describe(lost: Sequence[float], params: Sequence[str]) -> str:
    """``m 3 %, I_yy 100 %, l_f 12 %``: one channel's shares for a log or a diagnostic."""
    return ", ".join(f"{SHORT_NAMES.get(p, p)} {100 * s:.0f} %" for p, s in zip(params, lost, strict=True))


def _fisher(S: np.ndarray, dS: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``Σ_f w_f tr(S⁻¹ ∂_i S S⁻¹ ∂_j S)`` as ``R Rᵀ``, ``R`` the whitened ``L⁻¹ ∂S L⁻ᴴ``'s real
    and imaginary parts. The parameters ride in the matrices' columns (one (k, p k) product
    per frequency, not p tiny ones) and the sum is a real product: numpy's batched products of
    tiny complex matrices cost several times as much."""
    p, K, k, _ = dS.shape
    linv = np.linalg.inv(np.linalg.cholesky(S))
    left = linv @ dS.transpose(1, 2, 0, 3).reshape(K, k, p * k)  # (K, a, (p, b)): L⁻¹ ∂S
    both = left.reshape(K, k * p, k) @ (linv.conj().swapaxes(-1, -2) * np.sqrt(w)[:, None, None])
    white = both.reshape(K, k, p, k).transpose(2, 0, 1, 3).reshape(p, -1)
    rows = np.concatenate([white.real, white.imag], axis=1)
    return rows @ rows.T


def _variances(info: np.ndarray, jac: np.ndarray, used: np.ndarray) -> np.ndarray:
    """(q,) ``diag(J F⁻¹ Jᵀ)`` over the ``used`` parameters (correlation form, ridged: a
    parameter the information cannot tell gets a variance of order 1/_RIDGE of its scale);
    infinite for a parameter that moves with one not used."""
    F = info[np.ix_(used, used)]
    scale = np.sqrt(np.diag(F))
    corr = F / np.outer(scale, scale)
    inv = np.linalg.inv(corr + _RIDGE * np.eye(corr.shape[0])) / np.outer(scale, scale)
    J = jac[:, used]
    out = np.einsum("qi,ij,qj->q", J, inv, J)
    return np.where(np.any(jac[:, ~used] != 0, axis=1), np.inf, out)


__all__ = ["SHORT_NAMES", "describe", "information_lost"]
