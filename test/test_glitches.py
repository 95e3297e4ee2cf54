"""Glitch gating (method/glitches.py): isolated wild samples are replaced and counted, genuine
samples of rough and heavy-tailed roads are not, and a sensor that mostly glitches is refused."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from rozyn_estimator.method import Estimate, PipelineConfig, estimate
from rozyn_estimator.method.glitches import MAX_SHARE, gate_glitches
from rozyn_estimator.online.records import OK, Update, update_values
from rozyn_estimator.vehicle import Vehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

FS = 100.0
SPEED = 27.8


@cache
def clean() -> tuple[np.ndarray, Estimate]:
    accel = Simulation(SimConfig(duration_s=30.0, seed=4, noise_std_mps2=0.05)).run(30.0).accel_mps2
    return accel, estimate(accel, FS, Vehicle(), PipelineConfig(), SPEED)


@pytest.mark.parametrize(("at", "channel", "value", "count"), [
    (slice(1500, 1501), 0, 1e6, (1, 0)),  # the glitch: one sample at 1e6 m/s²
    (slice(10, 11), 1, 1e300, (0, 1)),  # near the float range's end (no overflow)
    (slice(1500, 1503), 0, -1e6, (3, 0)),  # a short run is still outvoted by its neighbours
    (slice(0, 1), 0, 1e6, (1, 0)),  # at the window's edge
])
def test_a_glitch_is_gated_and_counted_and_the_estimate_is_unharmed(at, channel, value, count):
    accel, reference = clean()
    glitched = accel.copy()
    glitched[at, channel] = value
    est = estimate(glitched, FS, Vehicle(), PipelineConfig(), SPEED, warm_start=reference)
    assert est.ok and est.stage == "likelihood" and est.glitches == count
    assert np.all(np.abs(est.params - reference.params) < 0.2 * reference.statistical_std)
    values = update_values(Update(stamp_ns=0, level=OK, message="", estimate=est, fs_hz=FS))
    assert (values["glitches_front"], values["glitches_rear"]) == tuple(str(n) for n in count)


def test_a_clean_window_gates_nothing():
    accel, reference = clean()
    assert reference.glitches == (0, 0)
    assert gate_glitches(accel)[1] == (0, 0)


@pytest.mark.parametrize(("nu", "rate_hz", "noise"),
                         [(3.0, 100.0, 0.0), (10.0, 100.0, 0.0), (10.0, 20.0, 0.0), (3.0, 1000.0, 0.05)])
def test_heavy_tailed_roads_are_not_glitches(nu, rate_hz, noise):
    """Laplace roads: loud sections reach hundreds of robust deviations, but never alone."""
    for seed in range(2):
        cfg = SimConfig(road=RoadSpec(kind="laplace", laplace_nu=nu), seed=seed, speed_kmh=60.0,
                        rate_hz=rate_hz, noise_std_mps2=noise, duration_s=40.0)
        accel = Simulation(cfg).run(40.0).accel_mps2
        assert gate_glitches(accel)[1] == (0, 0)


def test_a_quantised_channel_is_not_a_glitch_storm():
    """Most samples on one value (median absolute deviation 0): the step is the scale."""
    t = np.arange(3000) / FS
    quantum = 0.01
    bursts = 0.4 * np.sin(2 * np.pi * 1.3 * t) * (np.sin(2 * np.pi * 0.05 * t) > 0.9)
    signal = np.round(bursts / quantum) * quantum
    accel = np.column_stack([signal, signal])
    assert gate_glitches(accel)[1] == (0, 0)


def test_a_sensor_that_mostly_glitches_is_refused():
    accel, _ = clean()
    faulty = accel.copy()
    n = int(2 * MAX_SHARE * len(faulty))
    faulty[np.linspace(0, len(faulty) - 1, n).astype(int), 1] = 1e6
    est = estimate(faulty, FS, Vehicle(), PipelineConfig(), SPEED)
    assert est.status == "failed"
    assert est.reason.startswith(f"rear channel: {n} of {len(faulty)} samples are isolated outliers")


def test_gating_leaves_the_input_untouched():
    accel, _ = clean()
    glitched = accel.copy()
    glitched[7, 0] = 1e6
    gated, counts = gate_glitches(glitched)
    assert counts == (1, 0) and glitched[7, 0] == 1e6
    assert abs(gated[7, 0] - np.median(accel[3:12, 0])) < np.ptp(accel[3:12, 0])


def test_the_full_car_gates_and_reports_a_glitch_per_corner():
    """Its estimate counts what the window's check gated, per channel, and /diagnostics says it."""
    from rozyn_estimator.method.pipeline import estimate
    from rozyn_estimator.online.records import layout_of
    from rozyn_estimator.vehicle_full import FullVehicle

    sim = SimConfig(model="full", duration_s=60.0, seed=4, noise_std_mps2=0.05)
    accel = Simulation(sim).run(60.0).accel_mps2
    cfg = PipelineConfig()
    reference = estimate(accel, FS, FullVehicle(), cfg, SPEED)
    glitched = accel.copy()
    glitched[700, 2] = 1e6
    est = estimate(glitched, FS, FullVehicle(), cfg, SPEED)
    assert reference.ok and reference.glitches == (0, 0, 0, 0)
    assert est.ok and est.glitches == (0, 0, 1, 0)
    assert est.stage == "likelihood" and np.all(np.abs(est.params - reference.params) < 0.2 * reference.std)
    values = update_values(Update(stamp_ns=0, level=OK, message="", estimate=est, fs_hz=FS),
                           layout_of(FullVehicle()))
    assert values["glitches_rear_left"] == "1" and values["glitches_front_left"] == "0"
