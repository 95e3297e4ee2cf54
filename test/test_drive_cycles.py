"""Drive cycles: the shipped standard cycles, a cycle file's checks, and the simulator
following a cycle (sim_node.drive_cycle)."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from sim_node.drive_cycle import load_drive_cycle, parse_drive_cycle
from sim_node.road import RoadSpec
from sim_node.simulation import GRAVITY_MPS2, SimConfig, Simulation


@pytest.mark.parametrize(("name", "duration_s", "length_km", "stops"),
                         [("udds", 1369, 11.99, 17), ("hwfet", 765, 16.51, 1), ("wltc3b", 1800, 23.27, 8)])
def test_the_shipped_cycles_are_the_standards(name, duration_s, length_km, stops):
    cycle = load_drive_cycle(name)
    assert cycle.duration_s == duration_s
    assert cycle.length_m / 1e3 == pytest.approx(length_km, rel=2e-3)
    v = cycle.speed_mps
    assert np.sum((v[1:] == 0) & (v[:-1] > 0)) == stops


def test_the_distance_is_the_speeds_integral_and_the_cycle_repeats():
    cycle = load_drive_cycle("udds")
    t = np.linspace(-50.0, 3000.0, 300_001)
    d = cycle.distance_at(t)
    assert np.max(np.abs(np.gradient(d, t) - cycle.speed_at(t))) < 0.02  # m/s, the slope at the kinks
    np.testing.assert_allclose(cycle.distance_at(t + cycle.duration_s) - d, cycle.length_m, rtol=1e-10)


def test_the_driver_follows_the_rows_with_a_continuous_acceleration_and_a_bounded_jerk():
    cycle = load_drive_cycle("udds")
    t = np.linspace(-50.0, 3000.0, 600_001)
    a = cycle.acceleration_at(t)
    assert np.max(np.abs(np.gradient(cycle.speed_at(t), t) - a)) < 0.01  # m/s², the speed's derivative
    jerk = np.abs(np.diff(a) / np.diff(t))
    rows = np.abs(np.diff(np.diff(cycle.speed_mps) / np.diff(cycle.time_s)))
    assert jerk.max() <= rows.max() * (1 + 1e-9)  # a row's change of acceleration per second, at most
    assert np.max(np.abs(np.diff(a))) < 0.01  # continuous: no step between samples 5 ms apart
    # the moving average passes through the cycle's steady stretches: 20 s of idling, then moving
    assert cycle.speed_at(np.array([10.0]))[0] == 0.0 and cycle.speed_at(np.array([40.0]))[0] > 5.0


@pytest.mark.parametrize(("text", "words"), [
    ("time,speed\n0,1\n", "expected time_s"),
    ("time_s,speed_kmh\n0,1\n0,2\n", "increase"),
    ("time_s,speed_kmh\n0,1\n1,-2\n", "0-150 m/s"),
    ("time_s,speed_kmh\n0,0\n1,0\n", "never moves"),
    ("time_s,speed_kmh\n0,1\n1,fast\n", "row 2"),
    ("# only a comment\n", "no header"),
])
def test_a_cycle_that_is_not_a_speed_trace_is_refused_with_the_reason(text, words):
    with pytest.raises(ConfigError, match=words):
        parse_drive_cycle(text, "bad")


def test_the_simulator_follows_the_cycle_and_the_car_rests_at_a_stop():
    sim = Simulation(SimConfig(drive_cycle_file="udds", road=RoadSpec(amplitudes="gaussian"), seed=1))
    block = sim.run(60.0)
    cycle = load_drive_cycle("udds")
    np.testing.assert_allclose(block.speed_mps, cycle.speed_at(block.t_s))
    rest = block.accel_mps2[(block.t_s > 2.0) & (block.t_s < 19.0)]  # UDDS idles for its first 20 s
    moving = block.accel_mps2[block.speed_mps > 5.0]
    assert np.abs(rest - GRAVITY_MPS2).max() < 1e-3 * moving.std()  # a level accelerometer at rest reads g
    with pytest.raises(ConfigError, match="drive_cycle_file: drive cycle 'nope': no such file"):
        SimConfig(drive_cycle_file="nope")
