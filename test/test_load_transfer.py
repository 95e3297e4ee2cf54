"""Accelerating and braking pitch the body: the simulator's load transfer (sim_node.load_transfer)
and the estimator's removal of it as a known input (rozyn_estimator.method.load_transfer)."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.body_model import pitch_index, second_order_model, sensor_rows
from rozyn_estimator.method import METHODS, estimate, pipeline
from rozyn_estimator.method.load_transfer import (
    fit_without_load_transfer,
    load_transfer_mps2,
    longitudinal_acceleration_mps2,
)
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle
from sim_node import simulation
from sim_node.load_transfer import pitch_moment_model
from sim_node.modal import static_state_of
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

HEIGHTS = {"cog_height_m": 0.55, "wheel_centre_height_m": 0.3}


def _flat_run(vehicle: Vehicle | FullVehicle, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """(the sensors' accelerations from the load transfer alone, the speed) on a flat road."""
    full = isinstance(vehicle, FullVehicle)
    cfg = SimConfig(model="full" if full else "half", full_vehicle=vehicle if full else None,
                    vehicle=Vehicle() if full else vehicle, drive_cycle_file="udds",
                    road=RoadSpec(kind="flat"), initial_state=(0.0,) * (14 if full else 8),
                    include_gravity=False)
    sim = Simulation(cfg)
    block = sim.run(seconds)
    return block.accel_mps2, block.speed_mps


def test_braking_pitches_the_nose_down():
    v = Vehicle(**HEIGHTS)
    model = pitch_moment_model(second_order_model(v), pitch_index(v), v.sprung_mass_kg, v.cog_height_m)
    q = static_state_of(model, np.array([-2.0]))[:4]  # braking at 2 m/s², held
    front, rear = sensor_rows(v) @ q
    assert q[pitch_index(v)] < 0.0 and front < 0.0 < rear  # nose down (pitch positive nose up)
    # the moment m h a_x against the pitch stiffness, within its corners' compliance
    assert -q[pitch_index(v)] == pytest.approx(v.sprung_mass_kg * 0.55 * 2.0 / 1.3e5, rel=0.5)


@pytest.mark.parametrize("vehicle", [Vehicle(**HEIGHTS), FullVehicle(cog_lateral_m=0.05, **HEIGHTS)],
                         ids=["half", "full"])
def test_the_estimators_prediction_is_the_simulators_response(vehicle):
    """Two implementations: the simulator's exact-discretised plant against the estimator's
    frequency response; they differ by the estimator's low-pass of the acceleration only."""
    accel, speed = _flat_run(vehicle, 300.0)
    assert np.sqrt(np.mean(accel**2)) > 1e-3  # the load transfer is there
    a_x = longitudinal_acceleration_mps2(speed, 100.0)
    predicted = load_transfer_mps2(vehicle, a_x, 100.0)
    assert np.sqrt(np.mean((accel - predicted) ** 2)) < 0.05 * np.sqrt(np.mean(accel**2))
    if isinstance(vehicle, FullVehicle):  # three sensors: their columns
        three = load_transfer_mps2(vehicle, a_x, 100.0, columns=(0, 2, 3))
        np.testing.assert_allclose(three, load_transfer_mps2(vehicle, a_x, 100.0)[:, [0, 2, 3]])


def test_without_heights_or_at_a_constant_speed_the_simulator_adds_nothing():
    for cfg in (SimConfig(drive_cycle_file="udds", seed=2), SimConfig(vehicle=Vehicle(**HEIGHTS), seed=2)):
        assert Simulation(cfg)._transfer is None


def test_the_fit_sees_the_window_less_the_load_transfer_and_predicts_again_where_it_moved(monkeypatch):
    vehicle = Vehicle(tolerances=Tolerances.none(), **HEIGHTS)
    cfg = SimConfig(vehicle=vehicle, drive_cycle_file="udds", road=RoadSpec(amplitudes="gaussian"), seed=3)
    with_transfer = Simulation(cfg).run(240.0)
    monkeypatch.setattr(simulation.Simulation, "_load_transfer", lambda self, x0: None)
    without = Simulation(cfg).run(240.0)
    transfer = with_transfer.accel_mps2 - without.accel_mps2
    seen: list[tuple[np.ndarray, object]] = []
    answers = iter([np.array([1100.0, 2000.0, 1.2]), np.array([1000.0, 2000.0, 1.2])])

    def fit(window: np.ndarray, warm: object) -> np.ndarray:
        seen.append((window, warm))
        return next(answers)

    y = with_transfer.accel_mps2 - with_transfer.accel_mps2.mean(axis=0)
    out = fit_without_load_transfer(y, 100.0, vehicle, with_transfer.speed_mps, None, fit, lambda p: p)
    assert len(seen) == 2 and seen[0][1] is None and seen[1][1] is not None  # again, warm from the first
    assert out[0] == 1000.0
    truth = without.accel_mps2 - without.accel_mps2.mean(axis=0)
    for window, _ in seen:  # predicted at 10 % off, then at the truth: both remove nearly all of it
        assert np.sqrt(np.mean((window - truth) ** 2)) < 0.15 * np.sqrt(np.mean(transfer**2))


def test_a_constant_speed_window_is_fitted_as_it_is():
    vehicle = Vehicle(**HEIGHTS)
    y = np.random.default_rng(1).standard_normal((6000, 2))
    calls = []
    fit_without_load_transfer(y, 100.0, vehicle, np.full(6000, 20.0), None,
                              lambda w, warm: calls.append(w) or np.array([1100.0, 2000.0, 1.2]), lambda p: p)
    assert len(calls) == 1 and calls[0] is y


def test_a_harsh_drivers_windows_estimate_as_without_the_load_transfer(monkeypatch):
    """A driver four times as jerky as the cycle's moving average: the estimate with the load
    transfer in the data is the estimate without it, to a tenth of its std."""
    monkeypatch.setattr("sim_node.drive_cycle.SMOOTHING_S", 0.25)
    vehicle = Vehicle(tolerances=Tolerances.none(), **HEIGHTS)
    cfg = SimConfig(vehicle=vehicle, drive_cycle_file="udds", road=RoadSpec(amplitudes="gaussian"), seed=4,
                    noise_std_mps2=0.025)
    window = slice(300 * 100, 420 * 100)
    runs = [Simulation(cfg).run(420.0)]
    monkeypatch.setattr(simulation.Simulation, "_load_transfer", lambda self, x0: None)
    runs.append(Simulation(cfg).run(420.0))
    moved = runs[0].accel_mps2 - runs[1].accel_mps2
    assert np.sqrt(np.mean(moved[window] ** 2)) > 0.01  # m/s²: there is a load transfer to remove
    with_it = estimate(runs[0].accel_mps2[window], 100.0, vehicle, METHODS["likelihood"],
                       speed_mps=runs[0].speed_mps[window])
    monkeypatch.setattr(pipeline, "carries_load_transfer", lambda vehicle, speed: False)
    without, kept = (estimate(r.accel_mps2[window], 100.0, vehicle, METHODS["likelihood"],
                              speed_mps=r.speed_mps[window]) for r in (runs[1], runs[0]))
    assert with_it.ok and without.ok and kept.ok
    assert np.all(np.abs(with_it.params - without.params) < 0.05 * without.std)
    assert np.any(np.abs(kept.params - without.params) > 0.2 * without.std)  # left in, it moves them
