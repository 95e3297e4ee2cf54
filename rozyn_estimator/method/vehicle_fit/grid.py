"""Where the full car's spectrum is evaluated, and the linear map from there to what the
likelihood compares with the periodogram: :func:`evaluation_map`.

The likelihood compares each (mean) periodogram ordinate with its expectation, S smoothed by
the taper's spectral window and the group's spread of bins: ``S + m₂ S''/2``
(:func:`averaging_matrix`; :func:`expected_periodogram_m2`).

Why a coarse grid. The model's cost is per frequency (and per aliasing term), and S is
smooth on the scale of the band's bins (a body resonance spans ~60 bins of a 120 s window,
the wheelbase delay's phase turns once over 10 Hz at 100 km/h). S is evaluated at equally
spaced nodes ``grid_hz`` apart and interpolated to the frequencies by Lagrange polynomials
through the 8 nearest nodes (degree 7; measured at 0.05 Hz spacing: 4e-5 of S at any speed,
the estimates moved by 0.002 of their std; cubic polynomials need half that spacing for the
same error); interpolation and
smoothing are one sparse matrix, applied to S and to every derivative alike. Nearly
noise-free data need S at every frequency (the fit checks; :mod:`.refine`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import sparse

from rozyn_estimator.method.likelihood.kept import Kept

ALIAS_SPACING_HZ = 0.2  # the aliases' nodes, when the band's are on a grid (every 4th of the default's)
Linear = Callable[[np.ndarray], np.ndarray]  # stacked (..., F, k, k) -> (..., nodes, k, k)


def evaluation_map(freq_hz: np.ndarray, m2_hz2: np.ndarray,
                   grid_hz: float = 0.0) -> tuple[np.ndarray, sparse.csr_array | None]:
    """(the frequencies S is evaluated at, the sparse map (K, nodes) from there to the
    expectations at ``freq_hz``; None: the identity). ``m2_hz2`` (K,) each ordinate's
    kernel's second moment; ``grid_hz`` the nodes' spacing (0, or not coarser than the
    frequencies': S at each)."""
    smooth = bool(np.any(m2_hz2 > 0)) and freq_hz.size > 1
    targets = extended(freq_hz) if smooth else freq_hz
    span = float(targets[-1] - targets[0])
    n_nodes = max(8, math.ceil(span / grid_hz - 1e-9) + 1) if grid_hz > 0 else targets.size
    if grid_hz <= 0 or n_nodes >= 0.75 * targets.size:
        return targets, (averaging_matrix(freq_hz, m2_hz2) if smooth else None)
    op = lagrange_matrix((targets - targets[0]) / grid_hz, n_nodes)
    if smooth:
        op = sparse.csr_array(averaging_matrix(freq_hz, m2_hz2) @ op)
    return targets[0] + grid_hz * np.arange(n_nodes), op


def apply(op: sparse.csr_array, m: np.ndarray) -> np.ndarray:
    """``op`` along the frequency axis (-3) of stacked matrices, contiguous."""
    return np.ascontiguousarray(map_bins(op, m))


def alias_map(nodes_hz: np.ndarray, spacing_hz: float) -> tuple[np.ndarray, Linear | None]:
    """(the aliasing terms' base frequencies: ``spacing_hz`` apart from the first of the
    ascending ``nodes_hz``, the last at or beyond the end; the interpolation from there to the
    nodes, None for ``spacing_hz`` 0 or not sparser than the nodes: the nodes themselves). The
    aliases (``f ± fs``, above 85 Hz at 100 Hz) are smoother still than the band, and carry a
    few per mille of its power: a cold start's coarse fit, whose band is at every (mean)
    frequency, takes them as sparsely as the fine fit."""
    n = nodes_hz.size
    if spacing_hz <= 0 or n < 2:
        return nodes_hz, None
    x = (nodes_hz - nodes_hz[0]) / spacing_hz  # the nodes' positions in alias spacings
    n_alias = max(8, math.ceil(x[-1] - 1e-9) + 1)
    if n_alias >= 0.75 * n:
        return nodes_hz, None
    op = lagrange_matrix(x, n_alias)
    return nodes_hz[0] + spacing_hz * np.arange(n_alias), lambda s: apply(op, s)


def extended(freq_hz: np.ndarray) -> np.ndarray:
    """``freq_hz`` with one more frequency beyond each end, at the end's own spacing."""
    return np.r_[2 * freq_hz[0] - freq_hz[1], freq_hz, 2 * freq_hz[-1] - freq_hz[-2]]


def _weights(freq_hz: np.ndarray, m2_hz2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(below, middle, above): each expectation's weights on S a step below, at and above."""
    step = np.diff(extended(freq_hz))
    h1, h2 = step[:-1], step[1:]
    below, above = m2_hz2 / (h1 * (h1 + h2)), m2_hz2 / (h2 * (h1 + h2))
    cap = np.minimum(1.0, 1.0 / np.maximum(below + above, 1e-300))
    below, above = below * cap, above * cap
    return below, 1.0 - below - above, above


def averaging_matrix(freq_hz: np.ndarray, m2_hz2: np.ndarray) -> sparse.csr_array:
    """The map (K, K + 2) from S at ``freq_hz`` extended a step beyond each end to the
    expected periodogram at ``freq_hz``: ``S + m₂ S''/2`` with S'' the (non-uniform) second
    difference. Its weights are kept non-negative (``m₂`` is about a tenth of the spacing's
    square here; where it were more, the average is capped): a positive definite S stays one.

    Why: the road drives the body's three motions through two processes (the tracks), so
    the road's part of S is nearly rank 2 and the directions it nearly lacks turn with
    frequency (the rear's delay, the resonances' phase). A periodogram averaged across that
    turn (the taper's window, groups of bins) has power there that S lacks; with quiet
    sensors the roll inertia absorbed it (+10-17 % at 100 km/h with 1 % noise)."""
    below, middle, above = _weights(freq_hz, m2_hz2)
    k = freq_hz.size
    return sparse.csr_array(sparse.diags_array([below, middle, above], offsets=[0, 1, 2], shape=(k, k + 2)))


def expected_periodogram_m2(taper: np.ndarray, fs_hz: float) -> float:
    """The second moment [Hz²] of a taper's spectral window: a tapered periodogram's ordinate
    expects ``∫ W(ν) S(f - ν) dν ≈ S(f) + m₂ S''(f) / 2`` (W symmetric, unit mass), and
    ``m₂ = Σ (Δw)² / (4π² Σ w²)`` in cycles per sample² (the window's rate of change; the
    taper reaches zero at its ends). Tukey 0.2: 0.71 bin²."""
    w = np.asarray(taper, dtype=float)
    return float(np.sum(np.diff(np.r_[0.0, w, 0.0]) ** 2) / np.sum(w * w) / (4.0 * np.pi**2) * fs_hz**2)


def map_bins(op: sparse.csr_array, m: np.ndarray) -> np.ndarray:
    """``op`` along the frequency axis (-3) of stacked 2x2 matrices; complex values as pairs
    of reals (the real map on twice the columns: half the work of scipy's complex product)."""
    moved = np.ascontiguousarray(np.moveaxis(m, -3, 0))
    flat = moved.reshape(moved.shape[0], -1)
    out = (op @ flat.view(float)).view(complex) if np.iscomplexobj(flat) else op @ flat
    return np.moveaxis(out.reshape(op.shape[0], *moved.shape[1:]), 0, -3)


def lagrange_matrix(x: np.ndarray, n_nodes: int) -> sparse.csr_array:
    """(x.size, n_nodes) the interpolation from equally spaced nodes to the positions ``x``
    (in node spacings; :func:`lagrange_weights`) as a sparse matrix, shared (read only): the
    windows of a drive ask for the same few, each about half a millisecond."""
    x = np.asarray(x, dtype=float)
    return _LAGRANGE.get((x, n_nodes), lambda: _lagrange_matrix(x, n_nodes))


_LAGRANGE = Kept(8)  # a window's: its fit's map, its aliases', S itself at the sampled frequencies, ...


def _lagrange_matrix(x: np.ndarray, n_nodes: int) -> sparse.csr_array:
    first, weights = lagrange_weights(x, n_nodes)
    cols = first[:, None] + np.arange(weights.shape[1])
    return sparse.csr_array((weights.ravel(), cols.ravel(), np.arange(0, weights.size + 1, weights.shape[1])),
                            shape=(x.size, n_nodes))


def lagrange_weights(x: np.ndarray, n_nodes: int, points: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Lagrange interpolation of degree ``points - 1`` from ``n_nodes`` equally spaced nodes
    to the positions ``x`` (in node spacings from the first node): (first node (n,), weights
    (n, points)) over the ``points`` nearest nodes (one-sided at the ends; exact at the nodes)."""
    points = min(points, n_nodes)
    x = np.asarray(x, dtype=float)
    first = np.clip(np.floor(x).astype(int) - (points // 2 - 1), 0, n_nodes - points)
    t = x - first  # position among the nodes first .. first + points - 1
    nodes = np.arange(points)
    w = np.ones((x.size, points))
    for j in nodes:
        for m in nodes[nodes != j]:
            w[:, j] *= (t - m) / (j - m)
    return first, w
