"""The model check's statistic, for either car: are the window's spectra, whitened by the
fitted model, white? (:func:`whiteness`)

Whitened spectra. With ``S = L Lᴴ`` the fitted model's spectral matrix and ``d`` the window's
(tapered, normalised) DFT, ``L⁻¹ d`` is, under the model, complex Gaussian with identity
covariance. In each of ``B`` log-spaced bands the mean ``M_b`` of the whitened periodogram
matrices should be the k×k identity; the complex-Wishart likelihood-ratio statistic

    T = Σ_b 2 n_b (tr M_b - ln det M_b - k)

is χ² for independent ordinates, ``n_b`` the band's ordinates over the taper's correlation of
neighbours (``κ = Σ_δ ρ_δ²``).

The model's resolution. The road drives the body through one input (the half car) or two
(the full car's tracks), so the road's part of S has that rank but for what the taper's
smoothing and the aliases fill in: a small part of S, which the model describes to a few
tens of per cent of itself (measured on noise-free in-model runs: the rear's residual given
the front at 3e-4 of S, the model's off by up to 40 % of that, band by band). Where the
sensors are quiet that part *is* the small directions' power, and the check saw the model's
approximation as a misfit (p < 0.001 in a quarter to all of noise-free half-car runs,
depending on the speed). So where the model's own content exceeds ``1 / RESOLUTION`` of a
small direction's power, white noise (a dither) is added to the data and to the model until
it does not: the check cannot resolve a departure below the model's accuracy, and does not
claim to. With real sensors' noise (10 % of the signal) nothing is added. The dither is
white noise's DFT under the window's taper (correlated between bins as the data are), and
pseudo-random, seeded by the window's data: a replay reproduces it.

Degrees of freedom. A fitted parameter absorbs the part of the statistic its changes of S
explain: with ``G`` the bands' whitened ``∂S`` (normalised like T's components), ``A`` the
fit's inverse information (its priors' precision included) and ``F`` the data's,
``E[T] = k² B − κ (2 tr(G A Gᵀ) − tr(G A F A Gᵀ))`` to first order: a parameter that moves
every band's mean alike absorbs a whole degree of freedom, one that reshapes S within the
bands (a resonance moving) nearly none, and a prior holds a calibrated value's absorption to
the data's share of it. The χ² takes these degrees of freedom (counting each parameter as
one made the check 5-10 % conservative where the fit absorbs less, and miss where the
calibration absorbs more).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import special

N_BANDS = 8
RESOLUTION = 10.0  # the small directions' power at least this times the model's own content there
NUMERICAL = 1e-10  # the model's content is taken as at least this share of S's largest: its arithmetic


@dataclass(frozen=True)
class Whiteness:
    """The statistic, its degrees of freedom and p-value, and per band its share and limits."""

    statistic: float
    dof: float
    p_value: float
    per_band: np.ndarray  # (B,) each band's part of the statistic
    edges_hz: np.ndarray  # (B + 1,) the bands' edges
    dithered: float  # the share of the frequencies where the model's resolution set a dither
    cross_share: np.ndarray  # (B,) of each band's part, what the channels' coherence carries
    quadrature: np.ndarray  # (B,) two channels: the coherence's misfit in quadrature to the model's (a delay)
    channels: int = 2


def band_edges(freq_hz: np.ndarray) -> np.ndarray:
    """``N_BANDS`` log-spaced bands over the frequencies (ascending)."""
    return np.geomspace(freq_hz[0], freq_hz[-1] * (1 + 1e-9), N_BANDS + 1)


Components = Callable[[np.ndarray | None, np.ndarray], np.ndarray]
_SAMPLE = 3  # the absorption from every 3rd group (it is smooth in frequency; as the fits' information)


def dither_factor(S: np.ndarray, floors: np.ndarray, rank: int,
                  unknown: np.ndarray | None = None) -> np.ndarray | None:
    """(K, k, k - rank) ``C`` with ``C Cᴴ`` the dither's spectral matrix: in the small directions
    of the road's part ``S - diag(floors)`` (all but its ``rank`` largest), what tops each
    direction's power up to ``RESOLUTION`` times the road's own content there (at least
    ``NUMERICAL`` of its largest: a direction noise-free sensors on a rigid body never move
    gets that much). ``unknown`` (k,): white floors the check took out of S because the fit ran
    them to their boundary (the data hold anywhere from none to about that much): the content is
    at least ``RESOLUTION`` times their part in a direction, so that what they leave unsaid is at
    most 1 % of the dither. None where the floors reach that everywhere (real sensors' noise)."""
    k = S.shape[-1]
    road = S - floors[:, None, :] * np.eye(k)
    if k == 2 and rank == 1:
        lam, small = _small_direction(road)
    else:
        lam, U = np.linalg.eigh(road)  # ascending: the small directions first
        small = U[:, :, : k - rank]
    content = np.maximum(lam[:, : k - rank], NUMERICAL * lam[:, -1:])
    if unknown is not None and np.any(unknown):
        untold = np.einsum("kai,a,kai->ki", small.conj(), np.asarray(unknown, float), small).real
        content = np.maximum(content, RESOLUTION * untold)
    noise = np.einsum("kai,ka,kai->ki", small.conj(), floors, small).real
    top_up = np.maximum(RESOLUTION * content - noise, 0.0)
    if not np.any(top_up):
        return None
    return small * np.sqrt(top_up)[:, None, :]


def _small_direction(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Of stacked 2x2 Hermitian ``m``: its eigenvalues (K, 2) ascending, and the small one's
    unit eigenvector (K, 2, 1), in closed form (numpy's eigh loops over the stack)."""
    a, d, b = m[:, 0, 0].real, m[:, 1, 1].real, m[:, 1, 0]
    r = np.sqrt(0.25 * (a - d) ** 2 + np.abs(b) ** 2)
    small = 0.5 * (a + d) - r
    # (m - λ) v = 0 from either row; the longer of the two is the better conditioned
    first = np.stack([-np.conj(b), (a - small).astype(complex)], axis=1)
    second = np.stack([(d - small).astype(complex), -b], axis=1)
    v = np.where((np.sum(np.abs(first) ** 2, axis=1) >= np.sum(np.abs(second) ** 2, axis=1))[:, None],
                 first, second)
    norm = np.sqrt(np.sum(np.abs(v) ** 2, axis=1))
    v = np.where(norm[:, None] > 0, v / np.where(norm > 0, norm, 1.0)[:, None], np.array([1.0, 0.0]))
    return np.stack([small, small + 2 * r], axis=1), v[:, :, None]


def _seeded(dft: np.ndarray) -> np.random.Generator:
    """A random stream that is a function of the window's data (a replay repeats it)."""
    digest = hashlib.blake2b(np.ascontiguousarray(dft).tobytes(), digest_size=8).digest()
    return np.random.default_rng(int.from_bytes(digest, "little"))


def dithered(dft: np.ndarray, C: np.ndarray, group: np.ndarray,
             window_dft: np.ndarray | None = None) -> np.ndarray:
    """(n, k) the DFT plus complex Gaussian noise of spectral matrix ``C Cᴴ`` (``C`` per group)
    per bin, correlated between neighbouring bins as the taper correlates the data's
    (``window_dft`` ``ŵ_j``, :class:`~.spectra.Spectra`'s: the noise is white noise's DFT under
    it, ``Σ_j ŵ_j z_(k-j)``). Independent noise would be worth κ times fewer ordinates than the
    statistic counts, and pull it low by that factor where the dither rules."""
    rng = _seeded(dft)
    w = np.ones(1) if window_dft is None else np.asarray(window_dft)
    w = w / math.sqrt(float(np.sum(np.abs(w) ** 2)))
    shape = (dft.shape[0] + w.size - 1, C.shape[-1])
    z = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2.0)
    if w.size > 1:
        z = np.stack([np.convolve(z[:, i], w, "valid") for i in range(shape[1])], axis=1)  # k ≤ 4 channels
    return dft + np.einsum("nai,ni->na", C[group], z)


def absorbed(C: np.ndarray, counts: np.ndarray, starts: np.ndarray, kappa: float, A: np.ndarray,
             F: np.ndarray) -> float:
    """The degrees of freedom the fit absorbs (module docstring): ``C`` (p, K, m) the real
    components of the whitened ``∂S`` of the p free parameters per group (their inner product
    ``tr(W_i W_j)``), ``A`` (p, p) the fit's inverse information, ``F`` (p, p) the data's."""
    total = np.add.reduceat(counts, starts)
    X = np.add.reduceat(C * counts[:, None], starts, axis=1) * (1.0 / np.sqrt(total * kappa))[:, None]
    gram = np.einsum("ibm,jbm->ij", X, X)
    return kappa * float(2.0 * np.sum(A * gram) - np.trace(A @ gram @ A @ F))


def whiteness(S: np.ndarray, floors: np.ndarray, rank: int, dft: np.ndarray, group: np.ndarray,
              counts: np.ndarray, freq_hz: np.ndarray, kappa: float, components: Components,
              A: np.ndarray, F: np.ndarray, unknown: np.ndarray | None = None,
              window_dft: np.ndarray | None = None) -> Whiteness:
    """The check's statistic at the fitted model.

    Args:
        S: (K, k, k) the fitted model's spectral matrices per group of bins (a group may be one bin).
        floors: (K, k) its white noise floors (S's part that is not the road's).
        rank: the road's inputs (1: one road; 2: two tracks).
        dft: (n, k) the window's normalised DFT at the band's bins.
        group: (n,) each bin's group, non-decreasing (a group is a run of neighbouring bins).
        counts: (K,) the bins per group.
        freq_hz: (K,) the groups' frequencies (ascending).
        kappa: the taper's correlation of neighbours.
        components: the free parameters' whitened ``∂S`` as real components (p, len(at), m) at
            the groups ``at`` (their inner product ``tr(W_i W_j)``), whitened by the given
            matrices (K, k, k), or by ``S`` itself for None (the fit's: what it has at hand).
        A: (p, p) the fit's inverse information (priors included); F: (p, p) the data's.
        unknown: (k,) floors taken out of S, the fit having run them to their boundary
            (:func:`dither_factor`).
        window_dft: the taper's DFT (:class:`~.spectra.Spectra`'s), for the dither's correlation.
    """
    k = S.shape[-1]
    C = dither_factor(S, floors, rank, unknown)
    check = S if C is None else S + C @ np.conj(np.swapaxes(C, -1, -2))
    linv = np.linalg.inv(np.linalg.cholesky(check))
    d = dft if C is None else dithered(dft, C, group, window_dft)
    x = np.einsum("nab,nb->na", linv[group], d)  # whitened per bin
    xx = x[:, :, None] * x[:, None, :].conj()
    first = np.flatnonzero(np.r_[True, np.diff(group) != 0])
    P = (xx if first.size == group.size else np.add.reduceat(xx, first, axis=0)) / counts[:, None, None]
    edges = band_edges(freq_hz)
    starts = np.searchsorted(freq_hz, edges[:-1])  # ascending: each band's groups are a run
    total = np.add.reduceat(counts, starts)
    M = np.add.reduceat(P * counts[:, None, None], starts, axis=0) / total[:, None, None]
    n = total / kappa
    sign, log_det = np.linalg.slogdet(M)
    trace = np.einsum("baa->b", M).real
    per_band = 2.0 * n * np.where(sign.real > 0, trace - log_det.real - k, np.inf)
    diagonal = np.einsum("baa->ba", M).real
    auto = np.sum(diagonal - np.log(diagonal) - 1.0, axis=1)
    full = trace - log_det.real - k
    cross_share = np.where(full > 0, 1.0 - auto / np.where(full > 0, full, 1.0), 0.0)
    quadrature = np.full(edges.size - 1, np.nan)
    if k == 2:  # the whitened cross term against the model's own cross term's phase
        turn = np.exp(-1j * np.angle(check[:, 1, 0]))
        Q = np.add.reduceat(turn * P[:, 1, 0] * counts, starts) / total
        quadrature = Q.imag**2 / np.maximum(np.abs(Q) ** 2, 1e-300)
    # every _SAMPLE-th group, each standing for its block's bins (the whole band where it is short)
    at = np.arange(0, counts.size, _SAMPLE if counts.size >= 50 * _SAMPLE else 1)
    sampled = np.add.reduceat(counts, at)
    parts = components(None if C is None else check, at)
    dof = max(1.0, k * k * N_BANDS - absorbed(parts, sampled, np.searchsorted(freq_hz[at], edges[:-1]),
                                              kappa, A, F))
    statistic = float(np.sum(per_band))
    p = float(special.chdtrc(dof, statistic)) if math.isfinite(statistic) else math.nan
    share = 0.0 if C is None else float(np.sum(counts * np.any(C != 0, axis=(1, 2))) / np.sum(counts))
    return Whiteness(statistic, dof, p, per_band, edges, share, cross_share, quadrature, k)
