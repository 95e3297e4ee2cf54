"""The likelihood refinement of the half car (its front and rear channels through the one
refinement, :func:`~rozyn_estimator.method.vehicle_fit.refine.refine`): its fit from poor and
missing starts, a warm start, its failures as statuses, and the pipeline around it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PARAM_NAMES, PipelineConfig, estimate
from rozyn_estimator.method.likelihood import LikelihoodConfig
from rozyn_estimator.method.likelihood.road_input import delay_characteristic
from rozyn_estimator.method.vehicle_fit.refine import refine as refine_vehicle
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

from conftest import TRUTH

SPEED = 100 / 3.6
EXACT = Vehicle(tolerances=Tolerances.none())  # the fit in-model: every assumed value exactly known


def refine(accel: np.ndarray, fs_hz: float, vehicle: Vehicle, start: np.ndarray | None, speed,
           config: LikelihoodConfig | None = None, warm=None):
    """The refinement of the half car's front and rear channels."""
    return refine_vehicle(accel, fs_hz, vehicle, (0, 1), start, speed, config, warm=warm)


def run(vehicle=None, seed=3, duration_s=100.0, noise=0.05, rate_hz=100.0, **sim):
    v = vehicle or Vehicle()
    cfg = SimConfig(vehicle=v, road=RoadSpec(amplitudes="gaussian"), seed=seed, duration_s=duration_s,
                    noise_std_mps2=noise, rate_hz=rate_hz, **sim)
    block = Simulation(cfg).run(duration_s)
    return block.accel_mps2, block.speed_mps


@pytest.fixture(scope="module")
def window():
    return run()


def test_delay_characteristic():
    w = np.linspace(1.0, 100.0, 50)
    assert np.allclose(delay_characteristic(w, 2.8, 10.0), np.exp(-1j * w * 0.28))
    varying = delay_characteristic(w, 2.8, 10.0 * (1 + 0.1 * np.sin(np.linspace(0, 20, 5000))))
    assert np.all(np.abs(varying) <= 1 + 1e-12)
    assert abs(varying[-1]) < 0.9  # the delay spread smears the phase at high frequency
    assert abs(varying[0] - np.exp(-1j * 0.28)) < 0.01


def test_refine_recovers_the_truth_from_a_poor_start(window):
    accel, speed = window
    ref = refine(accel, 100.0, EXACT, np.array([800.0, 2600.0, 1.5]), speed)
    assert ref.ok, ref.reason
    assert np.all(np.abs(ref.params / TRUTH - 1) < 0.01)
    std = np.sqrt(np.diag(ref.covariance))
    assert np.all(std / TRUTH < 0.005) and np.all(std > 0)
    assert np.all(np.abs(ref.params - TRUTH) < 5 * std)
    assert 0.03 < ref.noise_std_mps2[0] < 0.07 and 0.03 < ref.noise_std_mps2[1] < 0.07  # 0.05 simulated
    assert abs(ref.waviness - 2.0) < 0.1
    json.dumps(ref.to_dict())


@pytest.mark.parametrize("start", [None, np.array([1000.0, 2000.0, 3.5])])
def test_without_a_usable_start_a_coarse_grid_starts_the_fit(window, start):
    accel, speed = window
    ref = refine(accel, 100.0, EXACT, start, speed)
    assert ref.ok and np.all(np.abs(ref.params / TRUTH - 1) < 0.01)


def test_white_noise_is_refused_as_noise():
    noise = np.random.default_rng(0).standard_normal((10_000, 2))
    ref = refine(noise, 100.0, EXACT, TRUTH, SPEED)
    assert ref.status == "failed" and "noise" in ref.reason


def test_warm_start_converges_faster_to_the_same_optimum(window):
    accel, speed = window
    cold = refine(accel, 100.0, EXACT, np.array([950.0, 2100.0, 1.25]), speed)
    warm = refine(accel, 100.0, EXACT, np.array([950.0, 2100.0, 1.25]), speed, warm=cold)
    assert cold.ok and warm.ok
    assert np.allclose(warm.params, cold.params, rtol=1e-4)
    assert warm.iterations < cold.iterations


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (dict(speed=-1.0), "positive speed"),
        (dict(speed=np.full(7, SPEED)), "speed: expected"),
        (dict(config=LikelihoodConfig(band_hz=(0.5, 0.8))), "too few frequencies"),
    ],
)
def test_refine_failures_are_statuses(window, args, words):
    accel, _ = window
    start, speed = args.get("start", TRUTH), args.get("speed", SPEED)
    ref = refine(accel, 100.0, EXACT, start, speed, args.get("config"))
    assert ref.status == "failed" and words in ref.reason and ref.params is None


@pytest.mark.parametrize(("changes", "field"), [({"band_hz": (2.0, 1.0)}, "band_hz"),
                                                 ({"aliases": -1}, "aliases"),
                                                 ({"taper": 1.5}, "taper")])
def test_invalid_likelihood_config(changes, field):
    with pytest.raises(ConfigError, match=field):
        LikelihoodConfig(**changes)


def test_pipeline_refines_and_keeps_rozyns_estimate(window):
    accel, speed = window
    est = estimate(accel, 100.0, EXACT, PipelineConfig(), speed_mps=speed)
    assert est.ok and est.stage == "likelihood" and not est.notes
    rozyn = estimate(accel, 100.0, EXACT, METHODS["rozyn"], speed_mps=speed)
    assert np.allclose(est.rozyn.params, rozyn.params) and est.rozyn_stage is est.rozyn
    assert rozyn.rozyn_stage is rozyn and rozyn.stage == "rozyn"
    assert np.all(np.abs(est.params / TRUTH - 1) < 0.01)
    assert len(est.modes) == 2
    record = json.loads(json.dumps(est.to_dict()))
    assert record["stage"] == "likelihood" and record["rozyn"]["mass_kg"] == pytest.approx(rozyn.params[0])
    assert record["refinement"]["status"] == "ok"



def test_the_budget_says_what_varies_between_windows_as_the_full_cars_does(window):
    """The data calibrate the sensors afresh in each window: that part of the tolerances' moves the
    estimate from window to window (a stop's load-change test counts it), on the half car too."""
    accel, speed = window
    est = estimate(accel, 100.0, Vehicle(), PipelineConfig(), speed_mps=speed)
    assert est.ok and est.budget is not None and est.budget.varying
    assert set(est.budget.varying) <= set(est.budget.contributions)
    between = np.diag(est.budget.between_windows)
    assert np.all(between > np.diag(est.budget.statistical)) and np.all(between <= np.diag(est.covariance))
    assert est.budget.names == est.names == PARAM_NAMES

def test_pipeline_falls_back_to_rozyn_with_a_warning(window):
    accel, _ = window
    est = estimate(accel, 100.0, EXACT, PipelineConfig())  # no speed: no wheelbase delay
    assert est.ok and est.stage == "rozyn"
    assert np.allclose(est.params, est.rozyn.params)
    assert "publishing the Rozyn estimate" in est.notes[0] and "speed" in est.notes[0]


@pytest.mark.parametrize("warm", [True, False])
def test_the_refinement_stands_in_for_a_failed_rozyn_stage(window, warm):
    accel, speed = window
    previous = estimate(accel, 100.0, EXACT, PipelineConfig(), speed_mps=speed)
    # Rozyn's stage finds no body modes in a band where there are none.
    strict = PipelineConfig(freq_band_hz=(5.0, 6.0))
    est = estimate(accel, 100.0, EXACT, strict, speed_mps=speed, warm_start=previous if warm else None)
    assert est.ok and est.stage == "likelihood" and est.rozyn.status == "failed"
    assert "Rozyn stage failed" in est.notes[0]
    assert ("previous estimate" if warm else "coarse grid") in est.notes[0]
    assert np.allclose(est.params, previous.params, rtol=1e-4)


def test_no_estimate_when_both_stages_fail():
    noise = np.random.default_rng(1).standard_normal((10_000, 2))
    est = estimate(noise, 100.0, EXACT, PipelineConfig(variance="none"), speed_mps=SPEED)
    assert est.status == "failed" and est.params is None
    assert "likelihood refinement failed" in est.reason


def test_free_decay_has_nothing_to_refine():
    with pytest.raises(ConfigError, match="refine"):
        PipelineConfig(correlation="free-decay")
