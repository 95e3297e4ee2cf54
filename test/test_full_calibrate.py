"""The full car's sensors calibrated by the data (method/vehicle_fit/uncertainty/calibrate.py,
sensing.py): the model's derivatives by the sensors' values, the copy that calibrates, and what
it is for — an uncertainty neither 10x too large on quiet data nor too small when a gain is off."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rozyn_estimator.method.budget import Calibration
from rozyn_estimator.method.pipeline import Estimate, PipelineConfig, estimate
from rozyn_estimator.method.vehicle_fit import refine
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.uncertainty import calibrate
from rozyn_estimator.method.vehicle_fit.uncertainty.calibrate import VehicleCalibration, sensor_groups
from rozyn_estimator.method.vehicle_fit.uncertainty.corners import CornerCalibrating, corner_keys
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

CAR = FullVehicle()
TRUTH = np.array([CAR.sprung_mass_kg, CAR.roll_inertia_kgm2, CAR.pitch_inertia_kgm2,
                  CAR.cog_from_front_axle_m, CAR.cog_lateral_m])
CALIBRATING = PipelineConfig()
FIRST_ORDER = dataclasses.replace(CALIBRATING, likelihood=dataclasses.replace(CALIBRATING.likelihood,
                                                                              self_calibrate=False))
ALL = ("gain", "x", "y", "delay")


def _model(**kw: object) -> tuple[VehicleSpectrum, np.ndarray]:
    model = VehicleSpectrum(CAR, (0, 1, 2, 3), np.linspace(0.5, 20.0, 60), 100.0, 27.0, **kw)  # type: ignore[arg-type]
    theta = model.theta(TRUTH, 1e-4, np.full(4, 1e-6))
    return model, theta


def test_derivatives_by_the_sensors_values_match_differences() -> None:
    model, theta = _model(calibrate=ALL)
    theta[model.calibration_slice] = np.random.default_rng(1).normal(0.0, 0.02, 13)
    _, dS = model.spectrum(theta)
    assert dS is not None
    for i in range(model.calibration_slice.start, model.n_params):
        up, down = theta.copy(), theta.copy()
        up[i] += 1e-6
        down[i] -= 1e-6
        diff = (model.spectrum(up, False)[0] - model.spectrum(down, False)[0]) / 2e-6
        assert np.abs(diff - dS[i]).max() <= 1e-5 * np.abs(dS[i]).max(), model.names[i]


def test_assumed_values_and_the_calibrating_copy_equal_the_fitted_ones() -> None:
    model, theta = _model(calibrate=ALL)
    values = np.random.default_rng(2).normal(0.0, 0.02, 13)
    theta[model.calibration_slice] = values
    S, dS = model.spectrum(theta)
    assumed, _ = _model(sensor_values=values)
    assert np.allclose(assumed.spectrum(theta[: assumed.n_params], False)[0], S, rtol=1e-12, atol=0)
    copy = assumed.calibrating(ALL)  # drops the assumed values: θ holds them
    S2, dS2 = copy.spectrum(theta)
    assert copy.names == model.names
    assert np.allclose(S2, S, rtol=1e-12, atol=0) and np.allclose(dS2, dS, rtol=1e-12, atol=0)


def test_groups_follow_the_tolerances() -> None:
    assert sensor_groups(CAR, (0, 1, 2, 3)) == ALL
    assert sensor_groups(CAR, (0, 1)) == ("gain", "x", "y")  # no rear sensor: no delay
    quiet = dataclasses.replace(CAR, tolerances=dataclasses.replace(
        CAR.tolerances, sensor_gain_front=0.0, sensor_gain_rear=0.0, sensor_lateral_m=0.0))
    assert sensor_groups(quiet, (0, 1, 2, 3)) == ("x", "delay")
    assert sensor_groups(dataclasses.replace(CAR, tolerances=FullTolerances.none()), (0, 1, 2, 3)) == ()
    assert isinstance(FullTolerances.none(), Tolerances)


@pytest.fixture(scope="module")
def quiet_drive() -> np.ndarray:
    sim = SimConfig(model="full", full_vehicle=CAR, road=RoadSpec(), speed_kmh=100.0, seed=1,
                    noise_std_mps2=0.005)
    return Simulation(sim).run(120.0).accel_mps2


def _fit(y: np.ndarray, cfg: PipelineConfig) -> tuple[np.ndarray, np.ndarray, Estimate]:
    e = estimate(y, 100.0, CAR, cfg, 100 / 3.6)
    assert e.ok and e.covariance is not None and e.params is not None and e.budget is not None
    return e.params - TRUTH, np.sqrt(np.diag(e.covariance)), e


def test_quiet_sensors_publish_what_the_data_know(quiet_drive: np.ndarray) -> None:
    """Quiet sensors (0.005 m/s²): the first-order budget put the roll inertia's and the lateral
    CoG's std at ~70 kg m² and ~10 mm, nearly all of it the sensors' gains and lateral positions;
    calibrated, the data take most of that back and the estimate stays within its std."""
    err, std, est = _fit(quiet_drive, CALIBRATING)
    _, first_std, _ = _fit(quiet_drive, FIRST_ORDER)
    assert std[1] < 0.85 * first_std[1] and std[4] < 0.2 * first_std[4]
    # the corner values calibrated too: the mass's std halves (what is left is the scale the data
    # cannot see: body and corners alike), the CoG's l_f a ninth of the first-order budget's
    assert std[0] < 0.7 * first_std[0] and std[3] < 0.3 * first_std[3]
    assert np.all(np.abs(err) < 2.0 * std)
    assert est.budget is not None
    sensors = [c for name, c in est.budget.contributions.items() if name.startswith("sensor")]
    assert len(sensors) == 13  # four gains, eight positions, the delay: still in the budget's groups
    assert est.budget is not None
    calibrated = est.budget.calibration
    assert {c.name for c in calibrated} >= {"sensor_gain_front_left", "sensor_y_rear_right_m",
                                            "sensor_time_offset_s"}
    delay = next(c for c in calibrated if c.name == "sensor_time_offset_s")
    assert delay.identified and abs(delay.estimate) < 3 * delay.std + 1e-6


def test_a_sensors_gain_off_by_its_tolerance_is_calibrated(quiet_drive: np.ndarray) -> None:
    """One sensor reading 2 % high (its tolerance): the first-order budget understated what it
    does to the roll inertia (an error of 0.6 std); calibrated, the gain's part of the error is
    gone (the estimate is the accurate sensors' to a fifth of its std)."""
    clean_err, _, _ = _fit(quiet_drive, CALIBRATING)
    y = quiet_drive.copy()
    y[:, 0] *= 1.02
    err, std, est = _fit(y, CALIBRATING)
    first_err, first_std, _ = _fit(y, FIRST_ORDER)
    assert abs(first_err[1]) > 0.5 * first_std[1]
    assert abs(err[1] - clean_err[1]) < 0.2 * std[1] and np.all(np.abs(err) < 2.0 * std)
    assert est.budget is not None
    gains = {c.name: c.estimate for c in est.budget.calibration if "gain" in c.name}
    assert max(gains, key=gains.__getitem__) == "sensor_gain_front_left"


def test_a_warm_update_takes_the_calibration_over_and_refreshes_it(quiet_drive: np.ndarray) -> None:
    first = estimate(quiet_drive[:-500], 100.0, CAR, CALIBRATING, 100 / 3.6)
    calibration = first.refinement.calibration
    assert calibration is not None and calibration.age == 0
    nxt = estimate(quiet_drive[500:], 100.0, CAR, CALIBRATING, 100 / 3.6, warm_start=first)
    taken = nxt.refinement.calibration
    assert taken is not None and taken.age == 1 and np.array_equal(taken.values, calibration.values)
    assert np.allclose(nxt.params[:4], first.params[:4], rtol=0.02)
    assert abs(nxt.params[4] - first.params[4]) < 1e-3
    old = dataclasses.replace(first, refinement=dataclasses.replace(
        first.refinement, calibration=dataclasses.replace(calibration, age=10)))
    fresh = estimate(quiet_drive[500:], 100.0, CAR, CALIBRATING, 100 / 3.6, warm_start=old)
    assert fresh.refinement.calibration is not None and fresh.refinement.calibration.age == 0


def test_a_value_far_beyond_its_tolerance_is_noted() -> None:
    far = Calibration("sensor_gain_front_left", 0.09, 0.004, 0.02)
    near = Calibration("sensor_y_front_right_m", 0.004, 0.002, 0.01)
    cal = VehicleCalibration(("gain", "y"), np.zeros(13), (far, near), {}, np.zeros(5))
    notes = cal.departures()
    assert len(notes) == 1 and "sensor_gain_front_left" in notes[0] and "+9" in notes[0]
    moved = np.zeros(14)
    assert cal.holds(moved) and not cal.holds(moved + 0.02)
    assert not dataclasses.replace(cal, age=10).holds(moved)


def test_derivatives_by_the_corner_values_match_differences() -> None:
    """The corner values' shares on a model that calibrates sensors too (their gains off: the
    corner derivatives must see θ's calibrated sensing)."""
    model, theta = _model(calibrate=("gain",))
    theta[model.calibration_slice] = np.random.default_rng(3).normal(0.0, 0.03, 4)
    keys = corner_keys(CAR)
    assert len(keys) == 10  # springs, dampers, tyres, tyre damping, unsprung masses per axle (no bars)
    calibrating = CornerCalibrating(model, CAR, keys)
    th = np.r_[theta, np.random.default_rng(4).normal(0.0, 0.1, len(keys))]
    S, dS = calibrating.node_spectrum(th)
    assert dS is not None and np.all(np.isfinite(S)) and dS.shape[0] == calibrating.n_params
    for i in range(model.n_params - 4, calibrating.n_params):
        up, down = th.copy(), th.copy()
        up[i] += 1e-6
        down[i] -= 1e-6
        diff = (calibrating.node_spectrum(up, False)[0] - calibrating.node_spectrum(down, False)[0]) / 2e-6
        assert np.abs(diff - dS[i]).max() <= 1e-5 * np.abs(dS[i]).max(), calibrating.names[i]
    # the body and every corner value scaled alike leave S as it is: the data cannot tell the
    # scale, only the tolerances bound it (the published mass std is theirs)
    scaled = th.copy()
    scaled[:3] += np.log1p(0.01)  # m, I_xx, I_yy 1 % more, and so every corner value
    scaled[model.n_params:] = 1.01 * (1.0 + th[model.n_params:]) - 1.0
    S2, _ = calibrating.node_spectrum(scaled, False)
    assert np.abs(S2 - S).max() < 1e-9 * np.abs(S).max()


def test_a_second_step_that_leaves_the_shares_range_is_not_taken() -> None:
    """The calibration's unchecked second step must keep every corner value a vehicle's."""
    model, theta = _model()
    calibrating = CornerCalibrating(model, CAR, corner_keys(CAR))
    inside = np.r_[theta, np.full(len(calibrating.keys), -0.5)]
    outside = inside.copy()
    outside[-1] = -0.95
    assert calibrate._shares_valid(calibrating, inside)
    assert not calibrate._shares_valid(calibrating, outside)


def test_a_corner_value_off_by_its_tolerance_is_calibrated() -> None:
    """The front tyres 10 % softer than the file says (their tolerance): calibrated, the data move
    the tyres' share toward the truth and the estimate stays within its std (here the model
    check still warns, so the corners' first-order budget stands in the covariance)."""
    plant = dataclasses.replace(CAR, tyre_stiffness_npm=(90_000.0, 90_000.0, 100_000.0, 100_000.0))
    sim = SimConfig(model="full", full_vehicle=plant, road=RoadSpec(), speed_kmh=100.0, seed=2,
                    noise_std_mps2=0.02)
    y = Simulation(sim).run(120.0).accel_mps2
    err, std, est = _fit(y, CALIBRATING)
    assert np.all(np.abs(err) < 3.0 * std), (err, std)
    assert est.budget is not None
    tyre = next(c for c in est.budget.calibration if c.name == "tyre_stiffness_front_npm")
    assert tyre.estimate < -0.05 and tyre.identified, tyre
    assert est.refinement is not None and est.refinement.calibration is not None
    assert est.refinement.calibration.vehicle(CAR).tyre_stiffness_npm[0] < 95_000.0


@pytest.mark.parametrize("seed, speed_kmh, tyre_npm", [(1, 100.0, 100_000.0), (2, 30.0, 90_000.0)])
def test_a_cold_fit_handed_over_to_the_calibration_ends_at_the_posteriors_mode(
        monkeypatch: pytest.MonkeyPatch, seed: int, speed_kmh: float, tyre_npm: float) -> None:
    """A cold fit stops within the calibration's one-step range (``HANDOFF``) and the
    calibration's Newton steps complete it: the estimates within 0.03 std of the posterior's
    mode, as the fit converged and the posterior scored to its mode find it (here 0.007 at
    most; the calibration's first step alone leaves 0.07, and up to 0.84 on 60 windows of
    the mismatch suite's cases, where the two steps left 0.07)."""
    plant = dataclasses.replace(CAR, tyre_stiffness_npm=(tyre_npm, tyre_npm, 100_000.0, 100_000.0))
    sim = SimConfig(model="full", full_vehicle=plant, road=RoadSpec(amplitudes="gaussian"), seed=seed,
                    speed_kmh=speed_kmh, noise_std_mps2=0.05)
    y = Simulation(sim).run(120.0).accel_mps2
    quick = estimate(y, 100.0, CAR, CALIBRATING, speed_kmh / 3.6)
    monkeypatch.setattr(refine, "HANDOFF", 0.0)  # the fit to its own tolerance
    monkeypatch.setattr(calibrate, "_SECOND_STEP", 0.0)  # the posterior scored ...
    monkeypatch.setattr(calibrate, "_CONVERGED", 1e-8)  # ... to its mode
    mode = estimate(y, 100.0, CAR, CALIBRATING, speed_kmh / 3.6)
    assert quick.stage == mode.stage == "likelihood"
    assert quick.params is not None and mode.params is not None and mode.covariance is not None
    off = (quick.params - mode.params) / np.sqrt(np.diag(mode.covariance))
    assert np.all(np.abs(off) < 0.03), off


def test_a_failed_calibration_leaves_the_fit_completed_and_the_first_order_budget(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """When the calibration fails, the fit it was to complete is completed without it: the
    estimate is the uncalibrated fit's (within 0.05 std), converged, with a note."""
    sim = SimConfig(model="full", full_vehicle=CAR, road=RoadSpec(amplitudes="gaussian"), seed=4,
                    noise_std_mps2=0.05)
    y = Simulation(sim).run(120.0).accel_mps2
    _, first_std, first = _fit(y, FIRST_ORDER)

    def fails(*args: object, **kwargs: object) -> None:
        raise ValueError("the posterior is not finite")

    monkeypatch.setattr(refine, "calibrate_vehicle", fails)
    _, std, est = _fit(y, CALIBRATING)
    assert est.params is not None and first.params is not None
    assert np.all(np.abs(est.params - first.params) < 0.05 * first_std)
    np.testing.assert_allclose(std, first_std, rtol=0.02)
    assert any(n.startswith("calibration failed (the posterior is not finite)") for n in est.notes)
    assert not any("not converged" in n for n in est.notes), est.notes


def test_an_optimiser_stopped_short_of_the_mode_is_a_failed_calibration(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A calibration whose optimiser stops short of the posterior's mode (its iterations spent,
    or its trust region collapsed: an urban window's corner values wandered to a tyre's
    stiffness at -29 % and moved l_f by +13 %, six std) is no calibration: the first-order
    budget stands, with a note, and the next window does not start from its values."""
    from scipy.optimize import OptimizeResult

    sim = SimConfig(model="full", full_vehicle=CAR, road=RoadSpec(amplitudes="gaussian"), seed=4,
                    noise_std_mps2=0.05)
    y = Simulation(sim).run(120.0).accel_mps2
    _, first_std, first = _fit(y, FIRST_ORDER)

    def short(objective: object, theta: np.ndarray, tol: float, max_iter: int,
              body: int = 0, near: bool = False) -> OptimizeResult:
        value = objective.fun(theta)  # type: ignore[attr-defined]
        return OptimizeResult(x=theta, fun=value, nit=max_iter, success=False)

    monkeypatch.setattr(calibrate, "_FAR", 0.0)  # no one-step estimator: the optimiser's route ...
    monkeypatch.setattr(calibrate, "_CONVERGED", 0.0)  # ... and it did not get there
    monkeypatch.setattr(calibrate, "scoring", short)
    _, std, est = _fit(y, CALIBRATING)
    assert est.refinement is not None and est.refinement.calibration is None
    stopped = "calibration failed (its optimiser stopped short of the posterior's mode after 100 iterations"
    assert any(n.startswith(stopped) for n in est.notes), est.notes
    assert est.params is not None and first.params is not None
    assert np.all(np.abs(est.params - first.params) < 0.05 * first_std)
    np.testing.assert_allclose(std, first_std, rtol=0.02)
