"""The full car's likelihood refinement (method.vehicle_fit.refine): its spectral model against the
simulator, its derivatives, the fit and its covariance, the warm start, the budget against a
wrong assumed value, and the fallbacks."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from spectrum_helpers import assert_slopes, model_response, plant_response

from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.method.pipeline import estimate
from rozyn_estimator.method.vehicle_fit.refine import _share_text, refine
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

ASYMMETRIC = FullVehicle(
    cog_lateral_m=0.08, cog_from_front_axle_m=1.3, roll_inertia_kgm2=450.0, track_rear_m=1.56,
    unsprung_mass_kg=(21.0, 19.0, 34.0, 31.0), suspension_stiffness_npm=(22e3, 24e3, 41e3, 38e3),
    anti_roll_stiffness_front_nmprad=15_000.0, anti_roll_stiffness_rear_nmprad=6000.0,
    sensor_x_m=(0.2, 0.1, 2.6, 2.7), sensor_y_m=(0.6, -0.5, 0.7, -0.65),
)
EXACT = dataclasses.replace(FullVehicle(), tolerances=FullTolerances.none())
RAISED = ASYMMETRIC.replace(cog_height_m=0.55, wheel_centre_height_m=0.3)  # gravity through the geometry
SPEED_MPS = 100 / 3.6


def _truth(v: FullVehicle) -> np.ndarray:
    return np.array([v.sprung_mass_kg, v.roll_inertia_kgm2, v.pitch_inertia_kgm2, v.cog_from_front_axle_m,
                     v.cog_lateral_m])


def _run(plant: FullVehicle, seed: int, noise: float = 0.1, duration_s: float = 120.0) -> np.ndarray:
    sim = SimConfig(model="full", full_vehicle=plant, road=RoadSpec(amplitudes="gaussian"), seed=seed)
    y = Simulation(sim).run(duration_s).accel_mps2
    return y + np.random.default_rng([seed, 9]).standard_normal(y.shape) * noise * y.std(axis=0)


def test_the_model_is_the_simulators_transfer_function():
    """G = iω P D⁻¹ Bᵀ T per unit road velocity equals the plant's state space (road height
    in, accelerations out) divided by iω, with every coupling at work."""
    f = np.linspace(0.3, 20.0, 40)
    model = VehicleSpectrum(RAISED, (0, 1, 2, 3), f, 100.0, 20.0, aliases=0)
    plant = plant_response(RAISED, f)
    theta = model.theta(_truth(RAISED), 1.0, np.ones(4))
    assert np.max(np.abs(model_response(model, theta) - plant)) < 1e-9 * np.max(np.abs(plant))


def test_the_derivatives_are_the_models_slopes():
    model = VehicleSpectrum(RAISED, (0, 1, 3), np.linspace(0.5, 15.0, 60), 100.0,
                            np.linspace(15.0, 25.0, 500), aliases=1)
    theta = model.theta(_truth(RAISED), 1e-4, np.full(3, 1e-3))
    theta[6:10] = [2.2, 0.1, -0.2, 0.3]  # waviness, road shape, coherence scale
    assert_slopes(model, theta, rtol=1e-6)


def test_the_refinement_is_far_sharper_than_rozyns_and_its_std_is_true():
    y = _run(EXACT, seed=5)
    est = estimate(y, 100.0, EXACT, PipelineConfig(), SPEED_MPS)
    rozyn = estimate(y, 100.0, EXACT, PipelineConfig(refine="none"), SPEED_MPS)
    assert est.ok and est.stage == "likelihood", est.reason
    assert est.std is not None and rozyn.std is not None
    z = (est.params - _truth(EXACT)) / est.std
    assert np.all(np.abs(z) < 4), z
    assert np.all(est.std < 0.3 * rozyn.std), est.std / rozyn.std
    assert est.std[0] < 0.01 * 1000 and est.std[4] < 0.005  # 1 % of the mass, 5 mm
    out = est.to_dict()
    assert out["stage"] == "likelihood" and out["refinement"]["status"] == "ok"
    assert out["rozyn"]["mass_kg"] == pytest.approx(est.rozyn.params[0])


def test_a_warm_start_on_the_same_window_needs_no_iteration():
    y = _run(EXACT, seed=6)
    cold = estimate(y, 100.0, EXACT, PipelineConfig(), SPEED_MPS)
    warm = estimate(y, 100.0, EXACT, PipelineConfig(), SPEED_MPS, warm_start=cold)
    assert cold.refinement is not None and warm.refinement is not None
    assert warm.refinement.iterations == 0 and cold.refinement.iterations > 0
    assert warm.params == pytest.approx(cold.params)


def test_three_sensors_and_an_asymmetric_car():
    plant = dataclasses.replace(ASYMMETRIC, tolerances=FullTolerances.none())
    y = _run(plant, seed=7)[:, [0, 1, 3]]
    est = estimate(y, 100.0, plant, PipelineConfig(), SPEED_MPS,
                        sensors=("front_left", "front_right", "rear_right"))
    assert est.ok and est.stage == "likelihood", est.reason
    assert est.std is not None
    assert np.all(np.abs((est.params - _truth(plant)) / est.std) < 4)


def test_the_budget_predicts_what_a_wrong_assumed_value_does():
    """The front springs 5 % stiffer than the vehicle file says, its tolerance 5 %: without the
    corners' calibration (``self_calibrate: false``) the estimate moves by the contribution the
    first-order budget published (opposite sign: the contribution is the assumed value moved by
    +1 tolerance)."""
    plant = dataclasses.replace(EXACT, suspension_stiffness_npm=(23_625.0, 23_625.0, 40_000.0, 40_000.0))
    assumed = dataclasses.replace(FullVehicle(), tolerances=FullTolerances.from_mapping(
        {"suspension_stiffness_front_npm": 0.05}))
    y = _run(plant, seed=8)
    cfg = PipelineConfig()
    cfg = dataclasses.replace(cfg, likelihood=dataclasses.replace(cfg.likelihood, self_calibrate=False))
    wrong = estimate(y, 100.0, assumed, cfg, SPEED_MPS)
    right = estimate(y, 100.0, plant, cfg, SPEED_MPS)
    assert wrong.refinement is not None and wrong.budget is not None
    contribution = wrong.refinement.contributions["suspension_stiffness_front_npm"]
    shift = wrong.params - right.params
    for i in (0, 2, 3):  # mass, pitch inertia, CoG: the spring's effect is well above the noise
        assert shift[i] == pytest.approx(-contribution[i], rel=0.2), i
    assert "suspension stiffness" in wrong.budget.to_dict()["contributors"]["mass_kg"]


def test_without_a_speed_rozyns_estimate_is_published_with_a_note():
    y = _run(EXACT, seed=5, duration_s=60.0)
    est = estimate(y, 100.0, EXACT, PipelineConfig(), None)
    assert est.ok and est.stage == "rozyn"
    assert est.refinement is not None and not est.refinement.ok
    assert "speed is unknown" in est.notes[0] and "publishing the Rozyn estimate" in est.notes[0]


def test_a_channel_that_is_only_noise_is_refused():
    y = _run(EXACT, seed=5, duration_s=60.0)
    y[:, 2] = np.random.default_rng(1).standard_normal(y.shape[0]) * y[:, 2].std()
    ref = refine(y, 100.0, EXACT, (0, 1, 2, 3), _truth(EXACT), SPEED_MPS)
    assert ref.status == "failed" and "rear_left channel as mostly noise" in ref.reason


@pytest.mark.parametrize(("accel", "match"), [
    (np.zeros((100, 4)), "too short"),
    (np.full((20_000, 4), np.nan), "NaN"),
    (np.ones((20_000, 4)), "constant"),
    (np.ones((20_000, 3)), r"shape \(n, 4\)"),
])
def test_bad_input_is_a_failed_status_with_a_reason(accel, match):
    est = estimate(accel, 100.0, FullVehicle(), PipelineConfig(), 27.0)
    assert est.status == "failed" and est.params is None
    assert re.search(match, est.reason), est.reason


def test_the_budgets_shortcut_keeps_the_contributions():
    """The budget sums over the evaluation grid's nodes (0.05 Hz apart): within 3 % of the
    sums over every frequency (of each parameter's largest contribution), as the model at
    every frequency (``grid_hz`` 0) takes them."""
    y = _run(FullVehicle(), seed=5)
    cfg = PipelineConfig()
    every = dataclasses.replace(cfg, likelihood=dataclasses.replace(cfg.likelihood, grid_hz=0.0))
    quick = estimate(y, 100.0, FullVehicle(), cfg, SPEED_MPS).refinement
    full = estimate(y, 100.0, FullVehicle(), every, SPEED_MPS).refinement
    assert quick is not None and full is not None and quick.contributions.keys() == full.contributions.keys()
    a, b = np.array(list(quick.contributions.values())), np.array(list(full.contributions.values()))
    assert np.all(np.abs(a - b) <= 0.03 * np.abs(b).max(axis=0)), np.abs(a - b) / np.abs(b).max(axis=0)


def test_the_half_cars_model_check_warns_when_its_sensors_see_the_roll():
    """The half car on a full car. Its centreline (each axle's two
    sensors averaged) fits; two sensors on the left side see the roll mode, and the half
    car's model check says so and names the full-vehicle model."""
    from rozyn_estimator.method import estimate
    from rozyn_estimator.vehicle_full import centreline_half_car

    y = _run(FullVehicle(), seed=1)
    half = centreline_half_car(FullVehicle())
    centre = estimate(np.column_stack([y[:, :2].mean(axis=1), y[:, 2:].mean(axis=1)]), 100.0, half,
                      PipelineConfig(), SPEED_MPS)
    left = estimate(y[:, [0, 2]], 100.0, half, PipelineConfig(), SPEED_MPS)
    assert centre.refinement is not None and left.refinement is not None
    assert centre.refinement.model_fit is not None and left.refinement.model_fit is not None
    assert centre.refinement.model_fit.verdict == "fits"
    assert "use the full-vehicle model" in left.refinement.model_fit.verdict
    assert any("use the full-vehicle model" in note for note in left.notes)


def test_a_poor_start_calls_for_the_grids_start_and_the_better_optimum_wins():
    """Rozyn's estimate of the full car can be far off (at 50 km/h a seed gave a third of the
    roll inertia, scoring from there stalled at a far worse likelihood): the grid's start
    runs too, and the lower ℓ wins."""
    sim = SimConfig(model="full", full_vehicle=EXACT, road=RoadSpec(amplitudes="gaussian"), speed_kmh=50.0,
                    seed=0)
    y = Simulation(sim).run(120.0).accel_mps2
    y = y + np.random.default_rng([0, 3]).standard_normal(y.shape) * 0.1 * y.std(axis=0)
    poor = np.array([856.0, 135.0, 1144.0, 1.055, 0.017])
    ref = refine(y - y.mean(axis=0), 100.0, EXACT, (0, 1, 2, 3), poor, 50 / 3.6)
    assert ref.ok and ref.starts >= 2 and not ref.notes, ref.reason
    assert ref.params is not None and ref.covariance is not None
    z = (ref.params - _truth(EXACT)) / np.sqrt(np.diag(ref.covariance))
    assert np.all(np.abs(z) < 4), z


def test_a_noise_share_reads_as_a_percent_or_as_times_when_far_beyond():
    """A floor gone astray reads "7.7e+79 times", not eighty digits of percent."""
    assert _share_text(0.654) == "65%"
    assert _share_text(7.7e79) == "7.7e+79 times"
