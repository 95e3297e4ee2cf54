"""Where the half car's spectrum is evaluated: :class:`Grid`, a coarse evaluation grid's
frequencies, and :class:`Reduction`, the sparse linear map from it to the periodograms'
expectations at the band's bins. Both depend on the window's length and rate only, and are
cached: consecutive windows of the same length share them.

Why. The model's cost is per frequency, and a 120 s window has 1 741 Fourier bins in the
band — but the spectral matrix is smooth on their scale: a body resonance spans ~60 bins,
the wheelbase delay's phase turns once over 10 Hz at 100 km/h (3 Hz at 30 km/h). So the
model is evaluated on every ``r``-th bin of the extended grid and interpolated to the bins
by Lagrange polynomials through the 8 nearest nodes (degree 7; measured at 0.05 Hz
spacing: 4e-5 of S at any speed, the estimates moved by 0.002 of their std; cubic
polynomials need half that spacing for the same error). The interpolation and the taper's
smoothing (``Σ_j |ŵ_j|² S(f_(k-j))``) are linear: one sparse matrix, built once per
window length, maps the evaluated spectra and every derivative to the bins.

Why not fewer ordinates too (a frequency-smoothed Whittle likelihood, the periodograms of
neighbouring bins averaged): with the sensors' noise at 10 % the front/rear spectral
matrix is nearly rank one, and each bin's periodogram carries its direction (the rear's
response relative to the front's) to within the noise; an average of rank-one matrices
whose direction turns across the block blurs exactly that. Measured: blocks of 0.05 Hz
(6 bins of a 120 s window) made the std of the mass 38 % larger.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.polynomial import legendre
from scipy import sparse


@dataclass(frozen=True)
class Reduction:
    """The evaluation grid (every ``step``-th bin of the extended grid) and the sparse map
    from it to the periodograms' expectations at the bins."""

    step: int  # bins between the evaluation grid's nodes
    to_bins: sparse.csr_array  # (k, n_eval): interpolation and the taper's smoothing

    to_nodes: sparse.csr_array  # (n_eval, k): the map's transpose (its adjoint)
    _rows: dict[tuple[int, ...], sparse.csr_array] = field(default_factory=dict, compare=False, repr=False)

    def rows(self, bins: tuple[int, ...]) -> sparse.csr_array:
        """The map's rows at ``bins`` only (cached per bin set)."""
        cached = self._rows.get(bins)
        if cached is None:
            cached = self._rows[bins] = sparse.csr_array(self.to_bins[list(bins)])
        return cached

    def bins(self, m: np.ndarray) -> np.ndarray:
        """Stacked (..., n_eval, 2, 2) on the evaluation grid -> the band's bins (..., k, 2, 2)."""
        return map_bins(self.to_bins, m)

    def adjoint(self, m: np.ndarray) -> np.ndarray:
        """Stacked (..., k, 2, 2) at the bins -> the nodes, by the map's transpose: for a
        gradient, ``Σ_k tr(bins(∂S)_k W_k) = Σ_m tr(∂S_m adjoint(W)_m)``."""
        return map_bins(self.to_nodes, m)


def map_bins(op: sparse.csr_array, m: np.ndarray) -> np.ndarray:
    """``op`` along the frequency axis (-3) of stacked 2x2 matrices; complex values as pairs
    of reals (the real map on twice the columns: half the work of scipy's complex product)."""
    moved = np.ascontiguousarray(np.moveaxis(m, -3, 0))
    flat = moved.reshape(moved.shape[0], -1)
    out = (op @ flat.view(float)).view(complex) if np.iscomplexobj(flat) else op @ flat
    return np.moveaxis(out.reshape(op.shape[0], *moved.shape[1:]), 0, -3)


@dataclass(frozen=True)
class Grid:
    """The frequencies the model is evaluated at: every ``step``-th bin of the band's bins
    extended by ``half`` bins each side (the taper's smoothing reaches that far, above 0 Hz),
    with their aliases ``f + a fs``, ``a = -A..A`` (read-only arrays: shared by the cache)."""

    kernel: np.ndarray  # (2 half + 1,) the taper's spectral window, trimmed to the extension, sums to 1
    half: int  # J: bins the grid extends beyond the band on each side
    n_eval: int  # nodes of the evaluation grid
    omega: np.ndarray  # (A n_eval,) signed angular frequency of each node and alias [rad/s]
    log_shape: np.ndarray  # (A n_eval,) log(|f| / f_ref): the road shape is exp((2 - w) log_shape + ...)
    shape_basis: np.ndarray  # (terms, A n_eval) Legendre polynomials of degree 2.. in log frequency


def evaluation_grid(freq_hz: np.ndarray, fs_hz: float, aliases: int, f_ref_hz: float,
                    window_weights: np.ndarray | None, step: int, road_shape_terms: int,
                    shape_edges_hz: tuple[float, float] | None) -> Grid:
    """The :class:`Grid` of a band's bins ``freq_hz`` (cached by all that defines it)."""
    weights = None if window_weights is None else np.asarray(window_weights, dtype=float).tobytes()
    edges = None if shape_edges_hz is None else (float(shape_edges_hz[0]), float(shape_edges_hz[1]))
    return _grid(np.asarray(freq_hz, dtype=float).tobytes(), float(fs_hz), int(aliases), float(f_ref_hz),
                 weights, int(step), int(road_shape_terms), edges)


@lru_cache(maxsize=16)
def _grid(freq_bytes: bytes, fs_hz: float, aliases: int, f_ref_hz: float, weights: bytes | None, step: int,
          road_shape_terms: int, shape_edges_hz: tuple[float, float] | None) -> Grid:
    freq_hz = np.frombuffer(freq_bytes)
    # A tapered periodogram's expectation is S smoothed by the taper's spectral window: the model
    # runs on the grid extended by J Fourier bins each side (above 0 Hz)
    c = np.ones(1) if weights is None else np.frombuffer(weights)
    half = (c.size - 1) // 2
    df = freq_hz[1] - freq_hz[0] if freq_hz.size > 1 else 1.0
    room = max(0, math.ceil(freq_hz[0] / df) - 1)
    if half > room:
        c = c[half - room: half + room + 1]
        half = room
    n_ext = freq_hz.size + 2 * half
    nodes = step * np.arange(node_count(n_ext, step))  # every step-th bin of the extended grid
    grid = freq_hz[0] + df * (nodes - half) if half or step > 1 else freq_hz
    shifts = np.arange(-aliases, aliases + 1)[:, None] * fs_hz
    f = (grid[None, :] + shifts).ravel()  # (A n_eval,) signed
    log_shape = np.log(np.abs(f) / f_ref_hz)
    # Legendre polynomials of degree 2.. in log frequency across the band (held at their edge
    # values at the aliases; continued smoothly over the few bins the grid extends beyond the
    # band, which the interpolation from a coarse grid needs): the road's departure from a power law.
    edges = np.log(np.array(shape_edges_hz or (freq_hz.min(), freq_hz.max())) / f_ref_hz)
    x = (2.0 * log_shape - edges.sum()) / (edges[1] - edges[0])
    aliased = np.repeat(np.arange(-aliases, aliases + 1) != 0, grid.size)
    x[aliased] = np.clip(x[aliased], -1.0, 1.0)
    degrees = range(2, road_shape_terms + 2)
    basis = np.array([legendre.legval(x, np.eye(road_shape_terms + 2)[d]) for d in degrees])
    out = Grid(c / c.sum(), half, nodes.size, 2.0 * np.pi * f, log_shape, basis)
    for a in (out.kernel, out.omega, out.log_shape, out.shape_basis):
        a.flags.writeable = False
    return out


def node_count(n_ext: int, step: int) -> int:
    """Nodes of the evaluation grid over ``n_ext`` bins (the last at or beyond the end)."""
    return n_ext if step == 1 else max(8, math.ceil((n_ext - 1) / step) + 1)


def reduction(n_bins: int, kernel: np.ndarray, step: int) -> Reduction:
    """The :class:`Reduction` of ``n_bins`` band bins smoothed by ``kernel`` (2J + 1 taps on
    the extended grid of ``n_bins + 2J`` bins), evaluated every ``step``."""
    return _reduction(n_bins, tuple(np.asarray(kernel, dtype=float).tolist()), int(step))


@lru_cache(maxsize=64)
def _reduction(n_bins: int, kernel: tuple[float, ...], step: int) -> Reduction:
    """Cached by window geometry: consecutive windows of a run share it (an online window's
    length jitters by a sample or two: built directly in CSR form, about a millisecond)."""
    taps = np.asarray(kernel)
    n_ext = n_bins + taps.size - 1
    n_nodes = node_count(n_ext, step)
    first, weights = _lagrange(n_ext, step, n_nodes)  # per fine bin: first node, (points,) weights
    # bin k is Σ_j taps_j · (fine bin k + j), each fine bin Σ_i weights_i · node (first + i):
    # a band of nodes starting at first[k] (first is non-decreasing)
    lo = first[:n_bins]
    width = int(np.max(first[taps.size - 1:] - lo)) + weights.shape[1]
    rows = np.arange(n_bins)
    # tap j of bin k reads fine bin k + j: sliding windows over the fine bins (views, no gather)
    first_at = sliding_window_view(first, taps.size)[:n_bins].T  # (taps, k)
    weights_at = sliding_window_view(weights, taps.size, axis=0)[:n_bins].transpose(2, 0, 1)  # like at
    at = (rows * width + first_at - lo)[:, :, None] + np.arange(weights.shape[1])  # (taps, k, points)
    values = taps[:, None, None] * weights_at
    block = np.bincount(at.ravel(), values.ravel(), minlength=n_bins * width).reshape(n_bins, width)
    cols = np.minimum(lo[:, None] + np.arange(width)[None, :], n_nodes - 1)  # padding (zeros) stays in range
    to_bins = sparse.csr_array((block.ravel(), cols.ravel(), np.arange(0, n_bins * width + 1, width)),
                               shape=(n_bins, n_nodes))
    to_bins.sum_duplicates()
    to_bins.eliminate_zeros()
    return Reduction(step, to_bins, sparse.csr_array(to_bins.T))


@lru_cache(maxsize=16)
def interpolation(n_ext: int, step: int) -> sparse.csr_array:
    """The sparse map from the evaluation grid's nodes (every ``step``-th of ``n_ext`` bins)
    to every bin of the extended grid, by the Lagrange polynomials alone (no smoothing)."""
    return lagrange_matrix(np.arange(n_ext) / step, node_count(n_ext, step))


def lagrange_matrix(x: np.ndarray, n_nodes: int) -> sparse.csr_array:
    """(x.size, n_nodes) the interpolation from equally spaced nodes to the positions ``x``
    (in node spacings; :func:`lagrange_weights`) as a sparse matrix."""
    first, weights = lagrange_weights(x, n_nodes)
    cols = first[:, None] + np.arange(weights.shape[1])
    return sparse.csr_array((weights.ravel(), cols.ravel(), np.arange(0, weights.size + 1, weights.shape[1])),
                            shape=(x.size, n_nodes))


def _lagrange(n_fine: int, step: int, n_nodes: int, points: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Lagrange interpolation from nodes at ``step`` spacing to every fine bin
    (:func:`lagrange_weights`; the identity for ``step`` 1)."""
    if step == 1:
        return np.arange(n_fine), np.ones((n_fine, 1))
    return lagrange_weights(np.arange(n_fine) / step, n_nodes, points)


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


def diagonal_part(m: np.ndarray) -> np.ndarray:
    """The diagonal part of stacked 2x2 matrices (..., 2, 2)."""
    out = np.zeros_like(m)
    out[..., 0, 0], out[..., 1, 1] = m[..., 0, 0], m[..., 1, 1]
    return out


def hermitian_part(m: np.ndarray) -> np.ndarray:
    """m + mᴴ per frequency (and row)."""
    return m + m.conj().swapaxes(-1, -2)
