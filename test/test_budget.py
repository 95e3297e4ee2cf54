"""The uncertainty budget (issue "Honest on a real vehicle"): tolerances, sensitivities,
self-calibration and the model-fit check, on single seeded windows (the statistics over
many roads are in the slow suite and `rozyn compare --suite mismatch`)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from rozyn_estimator.method import METHODS, PipelineConfig, estimate
from rozyn_estimator.method.budget import Budget, rozyn_contributions
from rozyn_estimator.method.likelihood import LikelihoodConfig
from rozyn_estimator.method.vehicle_fit.refine import refine as refine_vehicle
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle
from sim_node.departures import Departures
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

SPEED = 100 / 3.6
START = np.array([1000.0, 2000.0, 1.2])
EXACT = Vehicle(tolerances=Tolerances.none())


def refine(y: np.ndarray, fs_hz: float, vehicle: Vehicle, start: np.ndarray, speed: float,
           config: LikelihoodConfig | None = None):
    """The refinement of the half car's front and rear channels."""
    return refine_vehicle(y, fs_hz, vehicle, (0, 1), start, speed, config)


def window(seed: int = 5, departures: Departures | None = None) -> np.ndarray:
    cfg = SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=seed, duration_s=120.0,
                    departures=departures or Departures())
    y = Simulation(cfg).run(120.0).accel_mps2
    return y + 0.1 * y.std(axis=0) * np.random.default_rng(seed).standard_normal(y.shape)


@pytest.fixture(scope="module")
def clean():
    return window()


def test_no_tolerances_is_the_estimator_as_before(clean):
    """tolerances {}: no budget, no calibration, the published covariance is the fit's."""
    est = estimate(clean, 100.0, EXACT, PipelineConfig(), SPEED)
    assert est.ok and est.budget is None and est.refinement.contributions == {}
    assert est.refinement.calibration is None and np.array_equal(est.covariance, est.refinement.covariance)
    rozyn = estimate(clean, 100.0, EXACT, METHODS["rozyn"], SPEED)
    assert rozyn.budget is None


@pytest.mark.parametrize("key", ["tyre_stiffness_front_npm", "unsprung_mass_rear_kg", "wheelbase_m",
                                 "sensor_rear_offset_m", "suspension_damping_front_nspm"])
def test_sensitivities_match_the_whole_refinement(clean, key):
    """With self-calibration off, a value's contribution is its sensitivity times its
    tolerance: checked against the refinement re-run with the value moved by 1 %."""
    cfg = LikelihoodConfig(self_calibrate=False)
    tol = Tolerances.from_mapping({key: 0.01})  # 1 % of a stiffness, damping or mass; 1 cm
    vehicle = EXACT.replace(tolerances=tol)
    base = refine(clean, 100.0, vehicle, START, SPEED, cfg)
    (contribution,) = base.contributions.values()
    delta = tol.absolute(vehicle)[key]
    moved = refine(clean, 100.0, vehicle.replace(**{key: getattr(vehicle, key) + delta}), START, SPEED, cfg)
    shift = moved.params - base.params
    # within 20 %, or within a tenth of the estimate's own std where the shift is small (the
    # estimator's expected sensitivity against one realisation's, and the optimiser's tolerance)
    std = np.sqrt(np.diag(base.covariance))
    assert np.all(np.abs(contribution - shift) <= 0.2 * np.abs(shift) + 0.1 * std), (contribution, shift, std)


def test_default_tolerances_widen_the_covariance_honestly(clean):
    est = estimate(clean, 100.0, Vehicle(), PipelineConfig(), SPEED)
    b = est.budget
    assert est.ok and b is not None
    assert np.allclose(est.covariance, b.statistical + b.systematic)
    stat, total = np.sqrt(np.diag(b.statistical)), est.std
    assert np.all(total > 3 * stat)  # the tolerances dominate the data's own spread
    assert np.all(np.abs(est.params / START - 1) < 2 * total / START)
    names = {c.name for c in b.calibration}
    assert {"sensor_time_offset_s", "sensor_gain_rear", "tyre_stiffness_front_npm"} <= names
    offset = next(c for c in b.calibration if c.name == "sensor_time_offset_s")
    assert offset.identified and abs(offset.estimate) < 4 * offset.std
    text = b.text(0)
    assert text.count(",") == 2 and "suspension" in text  # the largest contributors, by name
    record = json.loads(json.dumps(est.to_dict()))
    assert set(record["budget"]) == {"statistical", "systematic", "contributors", "calibration"}
    assert record["refinement"]["model_fit"]["verdict"] == "fits"


def test_rozyn_stage_budget_is_its_linear_fits_sensitivity(clean):
    est = estimate(clean, 100.0, Vehicle(), METHODS["rozyn"], SPEED)
    b = est.budget
    assert b is not None and np.allclose(est.covariance, b.statistical + b.systematic)
    key, u = "tyre_stiffness_front_npm", 2000.0
    (c,) = rozyn_contributions(EXACT, est.modes, est.params, "eq2-22", "modal",
                               tolerances={key: u / 200_000.0}).values()  # as a share
    moved = rozyn_contributions(EXACT.replace(tyre_stiffness_front_npm=200_000.0 + u), est.modes, est.params,
                                "eq2-22", "modal", tolerances={key: 1e-9})
    assert np.allclose(c, b.contributions[key] * u / b_tolerance(key), rtol=1e-6)
    assert all(np.all(np.isfinite(v)) for v in moved.values())


def b_tolerance(key: str) -> float:
    return Tolerances().absolute(Vehicle())[key]


def test_a_late_rear_sensor_is_calibrated_and_reported():
    y = window(departures=Departures(time_offset_s=0.005))
    vehicle = EXACT.replace(tolerances=Tolerances.from_mapping({"sensor_time_offset_s": 0.005}))
    ref = refine(y, 100.0, vehicle, START, SPEED)
    (offset,) = ref.calibration.calibrations
    assert offset.name == "sensor_time_offset_s" and abs(offset.estimate - 0.005) < 4 * offset.std
    assert offset.identified and offset.text().startswith("+4.9")  # ms
    assert ref.model_fit.ok  # calibrated, the model fits
    blind = refine(y, 100.0, EXACT, START, SPEED)  # not told it may be late: the spectra do not fit
    assert not blind.model_fit.ok and "does not fit" in blind.model_fit.verdict


def test_asymmetric_dampers_fail_the_model_fit_check(clean):
    assert refine(clean, 100.0, EXACT, START, SPEED).model_fit.ok
    y = window(departures=Departures(damper_ratio=2.0))
    fit = refine(y, 100.0, EXACT, START, SPEED).model_fit
    assert not fit.ok and fit.p_value < 1e-4 and "nonlinear suspension" in fit.verdict


def test_a_model_fit_check_on_a_singular_spectrum_is_not_computable_not_fits(clean, monkeypatch):
    from rozyn_estimator.method.vehicle_fit import fitcheck

    real = fitcheck.whiteness

    def singular_at_one_bin(S, *args):
        S = S.copy()
        S[3] = 0.0  # no noise, no road there: no Cholesky factor
        return real(S, *args)

    monkeypatch.setattr(fitcheck, "whiteness", singular_at_one_bin)
    fit = refine(clean, 100.0, EXACT, START, SPEED).model_fit
    assert fit is not None and not fit.ok and fit.verdict == fitcheck.NOT_COMPUTABLE
    record = fit.to_dict()
    assert record["statistic"] is None and record["p"] is None
    json.dumps(record, allow_nan=False)  # valid JSON


def test_a_model_fit_check_whose_statistic_is_not_a_number_gives_no_verdict(clean, monkeypatch):
    """Whatever makes the statistic NaN or infinite, the check says it could not be computed:
    a NaN's p-value is never below the threshold, which would otherwise read as "fits"."""
    from rozyn_estimator.method.likelihood import fitcheck
    from rozyn_estimator.method.vehicle_fit import refine as one

    monkeypatch.setattr(one, "neighbour_correlation", lambda window_dft: math.nan)
    fit = refine(clean, 100.0, EXACT, START, SPEED).model_fit
    assert fit is not None and not fit.ok and fit.verdict == fitcheck.NOT_COMPUTABLE
    assert fit.to_dict()["statistic"] is None


def test_budget_groups_and_text():
    b = Budget(np.diag([1.0, 4.0, 1e-6]), {"tyre_stiffness_front_npm": np.array([3.0, 0.0, 0.0]),
                                           "tyre_stiffness_rear_npm": np.array([4.0, 0.0, 0.0]),
                                           "wheelbase_m": np.array([0.5, 1.0, 0.0])})
    assert b.by_group(0)[0] == ("tyre stiffness", 5.0)
    assert b.text(0) == "tyre stiffness 5, statistics 1, wheelbase 0.5"
    assert np.allclose(b.total, np.diag([1.0, 4.0, 1e-6]) + b.systematic)
    assert dataclasses.replace(b, contributions={}).text(1) == "statistics 2"
