"""The full car's refinement at less cost (issue 13: one refined update within 3x the half
car's): S evaluated on a coarse grid and interpolated (aliases on a coarser one still), the
gradient through the map's adjoint, the optimiser's Hessian over every 3rd frequency, a cold
start's first fit on coarser means, and the corners' values' contributions to the budget by
analytic derivatives. Each must leave the estimates, their covariance and the budget as
the exact computation gives them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.method.pipeline import estimate
from rozyn_estimator.method.vehicle_fit import whittle
from rozyn_estimator.method.vehicle_fit.corner_matrices import (
    corner_matrices,
    corner_matrix_derivatives,
    corner_response_derivatives,
)
from rozyn_estimator.method.vehicle_fit.grid import ALIAS_SPACING_HZ, alias_map
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.uncertainty import refine_budget
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

EXACT = dataclasses.replace(FullVehicle(), tolerances=FullTolerances.none())
BARS = dataclasses.replace(FullVehicle(), anti_roll_stiffness_front_nmprad=18_000.0,
                           anti_roll_stiffness_rear_nmprad=7000.0)


def _window(seed: int, speed_kmh: float = 100.0, noise: float = 0.1) -> tuple[np.ndarray, float]:
    sim = SimConfig(model="full", full_vehicle=FullVehicle(), road=RoadSpec(amplitudes="gaussian"),
                    seed=seed, speed_kmh=speed_kmh)
    y = Simulation(sim).run(120.0).accel_mps2
    y = y + np.random.default_rng([seed, 3]).standard_normal(y.shape) * noise * y.std(axis=0)
    return y, speed_kmh / 3.6


def _every_frequency(cfg: PipelineConfig) -> PipelineConfig:
    return dataclasses.replace(cfg, likelihood=dataclasses.replace(cfg.likelihood, grid_hz=0.0))


@pytest.mark.parametrize("seed, speed_kmh", [(1, 100.0), (2, 30.0)])
def test_the_grid_leaves_the_estimate_and_its_covariance(seed, speed_kmh):
    """Against S at every frequency (and the exact Hessian, no coarse first fit): the
    estimates within 0.05 of their std (the fit's tolerance), the std within 0.5 %."""
    y, v = _window(seed, speed_kmh)
    quick = estimate(y, 100.0, FullVehicle(), PipelineConfig(), v)
    exact = estimate(y, 100.0, FullVehicle(), _every_frequency(PipelineConfig()), v)
    assert quick.stage == exact.stage == "likelihood"
    assert quick.refinement is not None and exact.refinement is not None
    std = np.sqrt(np.diag(exact.refinement.covariance))
    assert np.all(np.abs(quick.refinement.params - exact.refinement.params) < 0.05 * std)
    np.testing.assert_allclose(np.sqrt(np.diag(quick.refinement.covariance)), std, rtol=5e-3)


def _model_and_theta(grid_hz: float) -> tuple[VehicleSpectrum, np.ndarray]:
    v = FullVehicle()
    freq = np.arange(0.5, 15.0, 1 / 60)
    model = VehicleSpectrum(v, (0, 1, 2, 3), freq, 100.0, 100 / 3.6, kernel_m2_hz2=5e-5, grid_hz=grid_hz)
    theta = model.theta(np.array([v.sprung_mass_kg, v.roll_inertia_kgm2, v.pitch_inertia_kgm2,
                                  v.cog_from_front_axle_m, v.cog_lateral_m]), 1e-6, np.full(4, 1e-6))
    theta[model.index["ln_coherence_scale"]] = 0.1
    return model, theta


def test_the_interpolated_model_is_the_model():
    """S from the 0.05 Hz grid (aliases at 0.2 Hz) within 1e-4 of S at every frequency."""
    quick, theta = _model_and_theta(0.05)
    exact, _ = _model_and_theta(0.0)
    assert quick.omega.size < exact.omega.size / 4
    S, _ = quick.spectrum(theta, derivatives=False)
    S0, _ = exact.spectrum(theta, derivatives=False)
    assert np.max(np.abs(S - S0)) < 1e-4 * np.max(np.abs(S0))


def test_the_gradient_through_the_adjoint_is_the_slope_of_the_likelihood():
    model, theta = _model_and_theta(0.05)
    S, _ = model.spectrum(theta, derivatives=False)
    rng = np.random.default_rng(4)
    x = rng.standard_normal((S.shape[0], 4, 8)) + 1j * rng.standard_normal((S.shape[0], 4, 8))
    periodogram = S @ (x @ x.conj().swapaxes(1, 2) / 8) @ S / np.trace(S, axis1=1, axis2=2)[:, None, None]
    objective = WhittleObjective(model, periodogram, np.full(S.shape[0], 2.0))
    grad = objective.jac(theta)
    for i in (0, 1, 3, 4, 5, model.index["ln_coherence_scale"], model.noise_slice.start):
        h = 1e-6
        step = np.zeros_like(theta)
        step[i] = h
        slope = (objective.fun(theta + step) - objective.fun(theta - step)) / (2 * h)
        assert grad[i] == pytest.approx(slope, rel=1e-4, abs=1e-6 * np.abs(grad).max()), i


def test_a_floors_levels_scored_together_are_the_likelihood_at_each():
    """floor_values' rank-one updates give ℓ as a fresh evaluation at each floor does, with a
    prior on the floor counted, and inf where S would not be positive definite."""
    model, theta = _model_and_theta(0.05)
    S, _ = model.spectrum(theta, derivatives=False)
    rng = np.random.default_rng(5)
    x = rng.standard_normal((S.shape[0], 4, 8)) + 1j * rng.standard_normal((S.shape[0], 4, 8))
    periodogram = S @ (x @ x.conj().swapaxes(1, 2) / 8) @ S / np.trace(S, axis1=1, axis2=2)[:, None, None]
    precision = np.zeros(model.n_params)
    precision[model.noise_slice.start + 2] = 0.5
    objective = WhittleObjective(model, periodogram, np.full(S.shape[0], 2.0), precision)
    floors = np.array([1e-9, 1e-7, 1e-5, 1e-3])
    for channel in (0, 2):
        fast = objective.floor_values(theta, channel, floors, model.noise_slice.start + channel)
        exact = []
        for floor in floors:
            trial = theta.copy()
            trial[model.noise_slice.start + channel] = np.log(floor)
            exact.append(objective.fun(trial))
        np.testing.assert_allclose(fast, exact, rtol=1e-9)
    # a floor S cannot take
    below = objective.floor_values(theta, 1, np.array([-1.0]), model.noise_slice.start + 1)
    assert not np.isfinite(below[0])


def test_the_optimisers_hessian_is_the_fisher_information_within_a_few_percent():
    model, theta = _model_and_theta(0.05)
    S, _ = model.spectrum(theta, derivatives=False)
    objective = WhittleObjective(model, S, np.full(S.shape[0], 2.0))
    fisher, hessian = objective.fisher(theta), objective.hess(theta)
    scale = np.sqrt(np.outer(np.diag(fisher), np.diag(fisher)))
    assert np.max(np.abs(hessian - fisher) / scale) < 0.03


def test_the_corner_matrices_derivatives_are_their_slopes():
    s = 2j * np.pi * np.linspace(0.5, 115.0, 60)
    base = np.concatenate([np.ravel(getattr(BARS, f)) for f in FullVehicle.CORNER_FIELDS])
    directions = np.random.default_rng(2).standard_normal((3, base.size)) * base
    dZ, dT = corner_matrix_derivatives(BARS, s, directions)
    h = 1e-6

    def at(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        values = {f: tuple(x[4 * i: 4 * i + 4]) for i, f in enumerate(FullVehicle.CORNER_FIELDS[:5])}
        values |= {FullVehicle.CORNER_FIELDS[5]: float(x[20]), FullVehicle.CORNER_FIELDS[6]: float(x[21])}
        return corner_matrices(dataclasses.replace(BARS, **values), s)

    for g, d in enumerate(directions):
        (z1, t1), (z0, t0) = at(base + h * d), at(base - h * d)
        np.testing.assert_allclose(dZ[g], (z1 - z0) / (2 * h), rtol=0, atol=1e-7 * np.abs(dZ[g]).max())
        np.testing.assert_allclose(dT[g], (t1 - t0) / (2 * h), rtol=0, atol=1e-7 * np.abs(dT[g]).max())


def test_the_corner_responses_derivatives_are_the_products_of_the_matrices_derivatives():
    """``left (dT r - dZ q)`` without forming dZ and dT: equal to the products of
    :func:`corner_matrix_derivatives`' matrices (the bars included)."""
    rng = np.random.default_rng(5)
    s = 2j * np.pi * np.linspace(0.5, 115.0, 40)
    base = np.concatenate([np.ravel(getattr(BARS, f)) for f in FullVehicle.CORNER_FIELDS])
    directions = rng.standard_normal((4, base.size)) * base

    def complex_normal(*shape: int) -> np.ndarray:
        return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)

    left, q, r = complex_normal(s.size, 3, 4), complex_normal(s.size, 4, 3), complex_normal(s.size, 4, 3)
    dZ, dT = corner_matrix_derivatives(BARS, s, directions)
    expected = left @ (dT @ r - dZ @ q)
    got = corner_response_derivatives(BARS, s, directions, left, q, r)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_the_analytic_contributions_are_the_differences(monkeypatch):
    """The corners' values' and the sensors' contributions by analytic derivatives equal
    those by moving the vehicle a small step (the geometry's are differences either way)."""
    y, v = _window(6)
    vehicle = BARS  # its bars carry their default tolerances
    analytic = estimate(y, 100.0, vehicle, PipelineConfig(), v).refinement
    monkeypatch.setattr(refine_budget, "_corner_direction", lambda *_: None)
    monkeypatch.setattr(refine_budget, "_sensor_change", lambda *_: None)
    stepped = estimate(y, 100.0, vehicle, PipelineConfig(), v).refinement
    assert analytic is not None and stepped is not None
    assert {"anti_roll_stiffness_front_nmprad", "sensor_time_offset_s", "sensor_gain_rear[rear_left]",
            "sensor_lateral_m[front_right]"} <= analytic.contributions.keys()
    assert analytic.contributions.keys() == stepped.contributions.keys()
    a, b = np.array(list(analytic.contributions.values())), np.array(list(stepped.contributions.values()))
    assert np.all(np.abs(a - b) <= 1e-3 * np.abs(b).max(axis=0)), np.abs(a - b) / np.abs(b).max(axis=0)


def test_the_budget_summed_over_every_third_frequency_is_the_whole_sum(monkeypatch):
    """The contributions' shared information summed as the optimiser's Hessian (every 3rd
    frequency, each for its neighbours) within 3 % of the sum over every frequency (of each
    parameter's largest contribution), the budget's total within 1 %."""
    y, v = _window(1)
    sampled = estimate(y, 100.0, FullVehicle(), PipelineConfig(), v).refinement
    monkeypatch.setattr(whittle, "_HESSIAN_STEP", 1)
    whole = estimate(y, 100.0, FullVehicle(), PipelineConfig(), v).refinement
    assert sampled is not None and whole is not None
    assert sampled.contributions.keys() == whole.contributions.keys()
    a, b = np.array(list(sampled.contributions.values())), np.array(list(whole.contributions.values()))
    assert np.all(np.abs(a - b) <= 0.03 * np.abs(b).max(axis=0)), np.abs(a - b) / np.abs(b).max(axis=0)
    np.testing.assert_allclose(np.sqrt((a**2).sum(axis=0)), np.sqrt((b**2).sum(axis=0)), rtol=0.01)


def test_the_aliases_nodes_interpolate_a_smooth_spectrum_on_uneven_band_nodes():
    """The aliases' nodes every 0.2 Hz from band nodes 0.1 Hz apart whose last two are uneven
    (a cold start's coarse means: the last group is shorter): a smooth function of frequency
    is recovered at every band node within 1e-6, from a third as many nodes."""
    nodes = np.r_[np.arange(0.45, 14.5, 0.1), 14.53, 14.61]
    base, fold = alias_map(nodes, ALIAS_SPACING_HZ)
    assert fold is not None and base.size <= nodes.size // 2 + 1 and base[-1] >= nodes[-1]
    smooth = np.exp(-0.05 * base) * np.cos(0.3 * base)
    values = np.broadcast_to(smooth[:, None, None], (base.size, 2, 2))
    exact = np.exp(-0.05 * nodes) * np.cos(0.3 * nodes)
    np.testing.assert_allclose(fold(values)[:, 0, 0], exact, rtol=0, atol=1e-6)
    assert alias_map(nodes, 0.0)[1] is None


def test_nearly_noise_free_data_are_fitted_at_every_frequency():
    """Noise floors near zero: the fit continues with S at every frequency (the grid's small
    errors matter where S is nearly singular), and its warm successor starts there."""
    y, v = _window(7, noise=0.0)
    est = estimate(y, 100.0, EXACT, PipelineConfig(), v)
    exact = estimate(y, 100.0, EXACT, _every_frequency(PipelineConfig()), v)
    assert est.refinement is not None and exact.refinement is not None
    std = np.sqrt(np.diag(exact.refinement.covariance))
    assert np.all(np.abs(est.refinement.params - exact.refinement.params) < 0.05 * std)
