"""The full car's published covariance is the sandwich with the score's covariance under the
model (method/vehicle_fit/score.py): untapered, on the fit's own S, it is the inverse Fisher
information; tapered its
sum by the midpoint rule is the sum over every pair of bins, and a warm update on a window
of the same length keeps its ratio."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import rozyn_estimator.method.vehicle_fit.refine as refine_module
import rozyn_estimator.method.vehicle_fit.score as score_module
from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.method.pipeline import estimate
from rozyn_estimator.method.vehicle_fit.score import score_covariance
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

EXACT = dataclasses.replace(FullVehicle(), tolerances=FullTolerances.none())


def _window(seed: int, speed_kmh: float) -> np.ndarray:
    sim = SimConfig(model="full", full_vehicle=EXACT, road=RoadSpec(amplitudes="gaussian"), seed=seed,
                    speed_kmh=speed_kmh)
    y = Simulation(sim).run(120.0).accel_mps2
    return y + np.random.default_rng([seed, 5]).standard_normal(y.shape) * 0.1 * y.std(axis=0)


def _fit(seed: int, speed_kmh: float, taper: float = 0.2) -> tuple:
    """(objective, θ, the physical parameters' directions jac F⁻¹, their model covariance
    jac F⁻¹ jacᵀ, spectra) of a fit (what the refinement hands to ``sandwich_ratio``)."""
    cfg = PipelineConfig()
    cfg = dataclasses.replace(cfg, likelihood=dataclasses.replace(cfg.likelihood, taper=taper))
    seen = {}
    original = refine_module.sandwich_ratio

    def capture(*args):
        seen["args"] = args
        return original(*args)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(refine_module, "sandwich_ratio", capture)
        est = estimate(_window(seed, speed_kmh), 100.0, EXACT, cfg, speed_kmh / 3.6)
    assert est.stage == "likelihood"
    return seen["args"]


@pytest.fixture(scope="module", params=[(1, 100.0), (2, 30.0)], ids=["100kmh", "30kmh"])
def fitted(request):
    return _fit(*request.param)


def _brute_force(objective, theta, combos, spectra) -> np.ndarray:
    """Σ over every bin k and every lag δ of Re tr(A_k C_(k,k+δ) A_(k+δ) C_(k+δ,k)), S evaluated
    at every bin (no grid), in double precision."""
    w_hat = spectra.window_dft
    n, reach = w_hat.size, (w_hat.size - 1) // 2
    df = spectra.fs_hz / spectra.n_samples
    K = spectra.freq_hz.size
    freq = spectra.freq_hz[0] + df * np.arange(-reach, K + reach)
    S_fine, _ = objective.model.regrid(freq, 0.0, 0.0).spectrum(theta, derivatives=False)
    _, dS, linv = objective.at(theta)
    inv = np.conj(np.swapaxes(linv, 1, 2)) @ linv
    A = np.repeat(inv @ np.tensordot(combos, dS, axes=1) @ inv, objective.counts.astype(int), axis=1)
    out = np.zeros((combos.shape[0],) * 2)
    idx = (np.arange(K)[None, :] + reach) - (np.arange(n)[:, None] - reach)
    for d in range(-(n - 1), n):
        j = np.arange(max(0, -d), min(n, n - d))
        prod = np.zeros(n, dtype=complex)
        prod[j] = w_hat[j] * np.conj(w_hat[j + d])
        C = np.tensordot(prod, S_fine[idx], axes=1)
        k = np.arange(max(0, -d), min(K, K - d))
        left = A[:, k] @ C[k][None]
        right = A[:, k + d] @ np.conj(np.swapaxes(C[k], 1, 2))[None]
        out += np.einsum("ikab,jkba->ij", left, right).real
    return out


@pytest.mark.parametrize("seed, speed_kmh", [(1, 100.0), (2, 30.0)])
def test_untapered_on_the_fits_own_spectrum_the_sum_is_the_fisher_information(seed, speed_kmh, monkeypatch):
    """The sum's machinery: with no taper (one lag) and the fit's own S at each bin of its
    groups, ``Σ_k tr(A_k S_k A_k S_k)`` is ``combos F combosᵀ = jac F⁻¹ jacᵀ``."""
    objective, theta, combos, model_cov, spectra = _fit(seed, speed_kmh, taper=0.0)
    assert spectra.window_dft.size == 1
    S, _, _ = objective.at(theta)
    monkeypatch.setattr(score_module, "fine_spectrum",
                        lambda *_: np.repeat(S, objective.counts.astype(int), axis=0))
    J = score_covariance(objective, theta, combos, spectra)
    np.testing.assert_allclose(np.sqrt(np.diag(J)), np.sqrt(np.diag(model_cov)), rtol=0.01)


def test_the_midpoint_rule_is_the_sum_over_every_pair_of_bins(fitted):
    objective, theta, combos, model_cov, spectra = fitted
    quick = score_covariance(objective, theta, combos, spectra)
    exact = _brute_force(objective, theta, combos, spectra)
    np.testing.assert_allclose(np.sqrt(np.diag(quick)), np.sqrt(np.diag(exact)), rtol=0.025)
    # and the taper matters: the mass's std differs from the model's times Dahlhaus' factor
    model = np.sqrt(np.diag(model_cov))
    assert not np.allclose(np.sqrt(np.diag(exact)), model, rtol=0.01)


def test_a_warm_update_keeps_the_ratio_only_on_a_window_as_long():
    y = _window(3, 100.0)
    cold = estimate(y, 100.0, EXACT, PipelineConfig(), 100 / 3.6)
    same = estimate(y, 100.0, EXACT, PipelineConfig(), 100 / 3.6, warm_start=cold)
    shorter = estimate(y[:-1000], 100.0, EXACT, PipelineConfig(), 100 / 3.6, warm_start=cold)
    assert cold.refinement is not None and same.refinement is not None and shorter.refinement is not None
    assert cold.refinement.sandwich is not None and shorter.refinement.sandwich is not None
    assert same.refinement.sandwich is cold.refinement.sandwich
    assert shorter.refinement.sandwich.n_samples != cold.refinement.sandwich.n_samples
    np.testing.assert_allclose(same.covariance, cold.covariance, rtol=1e-9)
