"""The model check's statistic (method/likelihood/whiteness.py) and its verdicts: χ² for data
the model describes, the dither only where the model's own resolution calls for it, the
degrees of freedom a fit absorbs, and a likely cause named only where its pattern singles it
out."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from rozyn_estimator.method.likelihood.fitcheck import misfit
from rozyn_estimator.method.likelihood.whiteness import (
    N_BANDS,
    RESOLUTION,
    Whiteness,
    absorbed,
    dither_factor,
    dithered,
    whiteness,
)

F = np.linspace(0.5, 15.0, 1700)


def dither_power(S: np.ndarray, floors: np.ndarray, rank: int,
                 unknown: np.ndarray | None = None) -> np.ndarray:
    """The dither's spectral matrix ``C Cᴴ`` (zero where there is none)."""
    C = dither_factor(S, floors, rank, unknown)
    return np.zeros_like(S) if C is None else C @ np.conj(np.swapaxes(C, -1, -2))


def _spectrum(small: float = 1e-4, floor: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(S, floors): a rank-one road part turning with frequency, a small part orthogonal to it
    (the model's own rank fill, ``small`` of the large), and white floors."""
    v = np.stack([np.ones_like(F), 0.8 * np.exp(-2j * np.pi * F * 0.1)], axis=1) / np.sqrt(1.64)
    u = np.stack([-np.conj(v[:, 1]), np.conj(v[:, 0])], axis=1)  # orthogonal to v at each frequency
    big = 1.0 / (1.0 + (F - 1.5) ** 2)
    outer = v[:, :, None] * v[:, None, :].conj() + small * u[:, :, None] * u[:, None, :].conj()
    S = big[:, None, None] * outer
    floors = np.full((F.size, 2), floor)
    return S + floors[:, None, :] * np.eye(2), floors


def _draw(S: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    L = np.linalg.cholesky(S)
    z = (rng.standard_normal((F.size, 2)) + 1j * rng.standard_normal((F.size, 2))) / np.sqrt(2.0)
    return np.einsum("kab,kb->ka", L, z)


def test_the_dither_tops_up_the_small_direction_only_where_the_models_own_content_rules_it():
    S, floors = _spectrum(small=1e-4, floor=0.0)
    D = dither_power(S, floors, rank=1)
    assert np.all(np.linalg.eigvalsh(D) >= -1e-15)  # positive semi-definite
    road = S - floors[:, None, :] * np.eye(2)
    lam, U = np.linalg.eigh(road)
    along_small = np.einsum("ka,kab,kb->k", U[:, :, 0].conj(), D, U[:, :, 0]).real
    along_large = np.einsum("ka,kab,kb->k", U[:, :, 1].conj(), D, U[:, :, 1]).real
    assert np.allclose(along_small, RESOLUTION * lam[:, 0], rtol=1e-6)
    assert np.allclose(along_large, 0.0, atol=1e-15)
    noisy, floors = _spectrum(small=1e-4, floor=1.0)  # real sensors' noise swamps the model's content
    assert not np.any(dither_power(noisy, floors, rank=1)) and dither_factor(noisy, floors, rank=1) is None
    lam, U = np.linalg.eigh(S[:, :, :] + 0.0)  # the closed form's small direction is numpy's
    C = dither_factor(S, np.zeros_like(floors), rank=1)
    assert C is not None and np.allclose(np.abs(np.einsum("kai,ka->k", C.conj(), U[:, :, 1])), 0.0, atol=1e-9)


def test_the_dither_is_correlated_between_bins_as_the_taper_correlates_the_data():
    """Independent dither would be worth κ times more ordinates than the statistic counts (the
    check would read low wherever the dither rules): it is white noise's DFT under the taper."""
    from rozyn_estimator.method.likelihood.fitcheck import neighbour_correlation
    from rozyn_estimator.method.likelihood.spectra import window_spectra

    spectra = window_spectra(np.random.default_rng(0).standard_normal((12000, 2)), 100.0, (0.5, 15.0), 0.2)
    kappa = neighbour_correlation(spectra.window_dft)
    assert kappa > 1.05  # a taper that correlates neighbours noticeably
    n = 40000
    C = np.broadcast_to(np.eye(2)[None, :, :1], (1, 2, 1))
    e = dithered(np.zeros((n, 2), complex), C, np.zeros(n, int), spectra.window_dft)[:, 0]
    assert abs(np.mean(np.abs(e) ** 2) - 1.0) < 0.03  # the power asked for
    p = np.abs(e) ** 2  # |e|² of neighbours correlate by |ρ_δ|²: their sum over lags is κ
    p = p - p.mean()
    lags = sum(np.mean(p[: n - d] * p[d:]) for d in range(1, 6))
    assert abs(1.0 + 2.0 * lags / np.mean(p * p) - kappa) < 0.03
    white = dithered(np.zeros((n, 2), complex), C, np.zeros(n, int))[:, 0]
    q = np.abs(white) ** 2 - np.mean(np.abs(white) ** 2)
    assert abs(np.mean(q[:-1] * q[1:]) / np.mean(q * q)) < 0.02  # without the taper: independent


def test_floors_taken_out_of_the_model_set_the_dither_well_above_what_they_may_leave_in_the_data():
    """A floor the fit ran to its boundary is taken out of S: the data may still hold up to about
    that much white power, which the dither must drown (at most 1 % of it), or the check would see
    the floor the model no longer has as a misfit."""
    S, floors = _spectrum(small=1e-12, floor=0.0)
    unknown = np.array([1e-6, 1e-6])
    D = dither_power(S, floors, rank=1, unknown=unknown)
    _, U = np.linalg.eigh(S)
    along_small = np.einsum("ka,kab,kb->k", U[:, :, 0].conj(), D, U[:, :, 0]).real
    assert np.allclose(along_small, RESOLUTION**2 * 1e-6, rtol=1e-6)  # the model's content is smaller
    assert np.allclose(dither_power(S, floors, rank=1, unknown=np.zeros(2)), dither_power(S, floors, rank=1))


def test_the_dither_is_a_function_of_the_data_with_the_covariance_asked_for():
    rng = np.random.default_rng(1)
    S, floors = _spectrum(small=1e-4)
    C = dither_factor(S, floors, rank=1)
    assert C is not None
    D = dither_power(S, floors, rank=1)
    assert np.allclose(C @ np.conj(np.swapaxes(C, -1, -2)), D)
    d = _draw(S, rng)
    bins = np.arange(F.size)
    a, b = dithered(d, C, bins), dithered(d, C, bins)
    assert np.array_equal(a, b)  # a replay repeats it
    assert not np.array_equal(dithered(d * 1.01, C, bins), a)  # other data, another draw
    e = a - d
    ratio = np.einsum("ka,kab,kb->k", e.conj(), np.linalg.pinv(D, hermitian=True), e).real
    assert abs(np.mean(ratio) - 1.0) < 0.05  # one complex degree of freedom: eᴴ D⁺ e ~ Exp(1)


def _statistic(S: np.ndarray, floors: np.ndarray, d: np.ndarray) -> Whiteness:
    def none(check: np.ndarray | None, at: np.ndarray) -> np.ndarray:  # no parameter fitted
        return np.zeros((0, at.size, 4))

    return whiteness(S, floors, 1, d, np.arange(F.size), np.ones(F.size), F, 1.0, none, np.zeros((0, 0)),
                     np.zeros((0, 0)))


@pytest.mark.parametrize("small", [1e-4, 0.3])  # quiet sensors (the dither works) and a full-rank S
def test_the_statistic_is_chi_squared_where_the_model_describes_the_data(small):
    rng = np.random.default_rng(7)
    S, floors = _spectrum(small=small)
    T = np.array([_statistic(S, floors, _draw(S, rng)).statistic for _ in range(300)])
    dof = 4 * N_BANDS
    assert abs(T.mean() - dof) < 4 * np.sqrt(2 * dof / T.size)
    assert stats.kstest(stats.chi2.sf(T, dof), "uniform").pvalue > 0.01


def test_a_misfit_in_the_small_direction_is_seen():
    rng = np.random.default_rng(3)
    S, floors = _spectrum(small=1e-4, floor=1e-2)  # noisy enough: no dither
    true, _ = _spectrum(small=1e-4, floor=1.3e-2)  # the data: 30 % more noise than the model has
    found = _statistic(S, floors, _draw(true, rng))
    assert found.p_value < 1e-6 and found.dithered == 0.0


def test_a_parameter_that_scales_every_band_absorbs_one_degree_of_freedom_one_that_reshapes_them_none():
    groups = np.ones(F.size)
    starts = np.searchsorted(F, np.geomspace(F[0], F[-1] * (1 + 1e-9), N_BANDS + 1)[:-1])
    # W = L⁻¹ ∂S L⁻ᴴ of S's scale is the identity: components (w11, w22, √2 Re w21, √2 Im w21)
    scale = np.broadcast_to(np.array([1.0, 1.0, 0.0, 0.0]), (1, F.size, 4))
    info = np.array([[2.0 * F.size]])  # Σ_k tr(W²)
    assert absorbed(scale, groups, starts, 1.0, 1.0 / info, info) == pytest.approx(1.0)
    sign = np.where(np.arange(F.size) % 2 == 0, 1.0, -1.0)  # + and - alternating within every band
    assert absorbed(scale * sign[None, :, None], groups, starts, 1.0, 1.0 / info, info) < 0.01
    prior = info + 3.0 * info  # a prior holding the value to a quarter of the data's variance
    held = absorbed(scale, groups, starts, 1.0, 1.0 / prior, info)
    assert held == pytest.approx(2 * 0.25 - 0.25**2)


def _found(per_band: list[float], cross: list[float], quadrature: list[float]) -> Whiteness:
    edges = np.geomspace(0.5, 15.0, N_BANDS + 1)
    return Whiteness(float(sum(per_band)), 24.0, 1e-9, np.array(per_band), edges, 0.0, np.array(cross),
                     np.array(quadrature), 2)


PATTERNS = [  # (per band, the coherence's share, its quadrature), what the verdict says and never says
    ([68, 102, 64, 45, 214, 391, 603, 403], [0.05, 0.1, 0.1, 0.4, 0.8, 1.0, 0.9, 1.0],
     [0.5] * 4 + [0.8, 1.0, 1.0, 1.0], "likely a time offset", "gain"),
    ([6, 17, 29, 11, 9, 12, 18, 7], [0.6, 0.8, 0.9, 0.8, 0.8, 0.9, 0.9, 0.6],
     [0.3, 0.1, 0.1, 0.3, 0.2, 0.1, 0.06, 0.05], "likely the sensors' relative gain", "time offset"),
    ([6, 6, 9, 7, 33, 4, 38, 7], [0.4, 0.5, 0.2, 0.3, 0.1, 0.7, 0.1, 0.7], [0.5] * 8,
     "power the road does not drive", "likely"),
    ([5, 19, 45, 10, 17, 11, 11, 20], [0.5, 0.9, 0.65, 0.5, 0.8, 0.9, 0.9, 0.4],
     [0.2, 0.6, 0.4, 0.2, 0.3, 0.5, 0.2, 0.7], "values (the suspension's stiffness and damping", "likely"),
    ([6, 6, 4, 9, 5, 14, 52, 23], [0.4, 0.5, 0.1, 0.9, 0.7, 0.95, 0.96, 0.96],
     [0.4, 0.4, 0.7, 0.2, 0.3, 0.7, 0.95, 0.02], "values (the tyres' stiffness and the unsprung", "likely"),
]


@pytest.mark.parametrize(("per_band", "cross", "quadrature", "says", "never"), PATTERNS)
def test_the_verdict_names_a_likely_cause_only_where_its_pattern_singles_it_out(
    per_band: list[float], cross: list[float], quadrature: list[float], says: str, never: str
) -> None:
    """Patterns like those measured at 10 % noise, 100 km/h (the rear sensor 5 ms late, its gain
    3 % low, dampers twice as stiff in rebound, the springs told 10 % stiff, the unsprung masses
    15 % heavy): the delay and the gain have their signature; the rest say where, and what to check."""
    found = _found(per_band, cross, quadrature)
    worst = int(np.argmax(per_band))
    band = (float(found.edges_hz[worst]), float(found.edges_hz[worst + 1]))
    text = misfit("half-car", 1e-9, band, found, "the rear sensor")
    assert says in text and never not in text
