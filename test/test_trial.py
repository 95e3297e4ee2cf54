"""Trial conditions of the robustness study: relative noise, bias, speed, suspension errors."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.tools.trial.run import estimate_block, run_trials, simulate
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.tools.trial.summary import summarise
from rozyn_estimator.vehicle import Vehicle

SHORT = dict(amplitudes="gaussian", duration_s=40.0)


def test_relative_noise_is_a_share_of_each_channels_rms():
    spec = TrialSpec(**SHORT)
    clean = simulate(spec, 4).accel_mps2
    noisy = simulate(spec.replace(noise_fraction=0.3), 4).accel_mps2
    added = noisy - clean
    assert np.allclose(added.std(axis=0) / clean.std(axis=0), 0.3, rtol=0.05)
    assert abs(np.corrcoef(added.T)[0, 1]) < 0.05  # independent channels


def test_bias_and_speed_variation_reach_the_sim():
    spec = TrialSpec(bias_mps2=(0.2, -0.3), speed_variation=0.1, **SHORT)
    block = simulate(spec, 1)
    base = simulate(TrialSpec(**SHORT), 1)
    assert np.allclose(block.accel_mps2.mean(axis=0) - base.accel_mps2.mean(axis=0), (0.2, -0.3), atol=0.01)
    assert block.speed_mps.max() / block.speed_mps.min() > 1.1


def test_estimator_vehicle_carries_the_suspension_errors():
    spec = TrialSpec(stiffness_error=0.1, damping_error=-0.1)
    told, true = spec.estimator_vehicle, spec.vehicle
    assert told.suspension_stiffness_rear_npm == pytest.approx(1.1 * true.suspension_stiffness_rear_npm)
    assert told.suspension_damping_front_nspm == pytest.approx(0.9 * true.suspension_damping_front_nspm)
    assert told.tyre_stiffness_front_npm == true.tyre_stiffness_front_npm
    plain = TrialSpec()
    assert plain.estimator_vehicle is plain.vehicle


def test_a_stiffness_error_moves_the_estimate():
    block = simulate(TrialSpec(noise_fraction=0.1, **SHORT), 2)
    right = estimate_block(TrialSpec(**SHORT), block, "likelihood")
    wrong = estimate_block(TrialSpec(stiffness_error=0.1, **SHORT), block, "likelihood")
    assert right.ok and wrong.ok
    assert wrong.params[0] - right.params[0] > 20.0  # kg; told stiffer -> heavier


@pytest.mark.parametrize(("changes", "field"), [({"noise_fraction": -0.1}, "noise_fraction"),
                                                 ({"stiffness_error": -1.0}, "stiffness_error"),
                                                 ({"speed_variation": 1.5}, "speed_variation"),
                                                 ({"bias_mps2": (0.0, float("nan"))}, "bias_mps2"),
                                                 ({"road": "gravel"}, "road: must be one of"),
                                                 ({"method": "nope"}, "method: must be one of"),
                                                 ({"duration_s": 0.0}, "duration_s: must be > 0 s"),
                                                 ({"damping_error": 10.0}, r"damping_error: .* \(-1, 10\)"),
                                                 ({"periodic": 1}, "periodic: expected true or false"),
                                                 ({"tyre_stiffness_error": -1.0}, "tyre_stiffness_error"),
                                                 ({"unsprung_mass_error": 10.0}, "unsprung_mass_error"),
                                                 ({"tyre_damping_error": float("nan")}, "tyre_damping_error"),
                                                 ({"departures": None}, "departures: expected Departures")])
def test_invalid_trial_options(changes, field):
    with pytest.raises(ConfigError, match=field):
        TrialSpec(**changes)


def test_free_decay_trial_skips_the_refinement():
    spec = TrialSpec(road="free-decay", duration_s=1.0, method="likelihood")
    assert spec.pipeline_config().refine == "none"
    (result,) = run_trials(spec, [1], jobs=1)
    assert result.estimate.ok and result.estimate.stage == "rozyn"


def test_summary_reports_coverage():
    """The statistical std (a vehicle known exactly: no tolerance budget on top)."""
    exact = Vehicle(tolerances=Tolerances.none())
    spec = TrialSpec(method="likelihood", noise_fraction=0.1, vehicle=exact, **SHORT)
    s = summarise(run_trials(spec, [1, 2, 3], jobs=1))
    assert s.failures == 0
    assert np.all((s.coverage_95 >= 0) & (s.coverage_95 <= 1))
    assert np.all(s.mean_reported_std < np.array([10.0, 25.0, 0.01]))


def test_other_vehicle_trial():
    v = Vehicle(sprung_mass_kg=1800.0, pitch_inertia_kgm2=3200.0, cog_from_front_axle_m=1.55, wheelbase_m=3.2)
    (r,) = run_trials(TrialSpec(vehicle=v, method="likelihood", noise_fraction=0.1, **SHORT), [5], jobs=1)
    assert r.estimate.ok and np.all(np.abs(r.estimate.params / r.truth - 1) < 0.02)
