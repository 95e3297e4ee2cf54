from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from sim_node.departures import Departures
from sim_node.road import RoadSpec
from sim_node.simulation import GRAVITY_MPS2, SimConfig, Simulation


def test_blocks_equal_one_run_including_noise():
    cfg = SimConfig(duration_s=20.0, noise_std_mps2=0.05, seed=3)
    whole = Simulation(cfg).run(20.0)
    sim = Simulation(cfg)
    parts = [sim.next_block(n) for n in (1, 0, 499, 1500)]
    accel = np.vstack([p.accel_mps2 for p in parts])
    assert np.allclose(accel, whole.accel_mps2, rtol=1e-12, atol=1e-12)
    assert np.allclose(np.concatenate([p.t_s for p in parts]), whole.t_s)
    assert whole.t_s[1] - whole.t_s[0] == pytest.approx(0.01)


def test_gravity_noise_and_bias():
    clean = Simulation(SimConfig(duration_s=50.0, include_gravity=False)).run(50.0).accel_mps2
    assert np.all(np.abs(clean.mean(axis=0)) < 0.01)
    cfg = SimConfig(duration_s=50.0, noise_std_mps2=0.2, bias_mps2=(0.1, -0.3))
    noisy = Simulation(cfg).run(50.0).accel_mps2
    assert noisy.mean(axis=0) == pytest.approx(np.array([0.1, -0.3]) + GRAVITY_MPS2, abs=0.02)
    assert np.std(noisy - clean - noisy.mean(axis=0) + clean.mean(axis=0)) == pytest.approx(0.2, rel=0.03)


def test_rear_sees_the_front_road_delayed():
    cfg = SimConfig(speed_kmh=36.0, duration_s=30.0)
    sim = Simulation(cfg)
    t = np.linspace(0, 20, 2001)
    s = sim.distance_m(t)
    front = sim.road.heights(s + cfg.vehicle.wheelbase_m)
    delay = cfg.vehicle.wheelbase_m / cfg.speed_mps
    assert np.allclose(sim.road.heights(sim.distance_m(t + delay)), front, atol=1e-12)


def test_seeds_and_speed_variation():
    a = Simulation(SimConfig(seed=1, duration_s=10.0)).run(10.0).accel_mps2
    b = Simulation(SimConfig(seed=2, duration_s=10.0)).run(10.0).accel_mps2
    assert not np.allclose(a, b)
    sim = Simulation(SimConfig(speed_variation=0.1, speed_period_s=20.0, duration_s=40.0))
    block = sim.run(40.0)
    assert block.speed_mps.max() == pytest.approx(100 / 3.6 * 1.1, rel=1e-3)
    assert np.allclose(np.gradient(sim.distance_m(block.t_s), block.t_s), block.speed_mps, rtol=1e-3)


def test_free_decay_starts_displaced_and_decays():
    block = Simulation(SimConfig(road=RoadSpec(kind="flat"), include_gravity=False)).run(5.0)
    a = np.abs(block.accel_mps2)
    assert a[:50].max() > 1.0 and a[-50:].max() < 1e-3


@pytest.mark.parametrize(
    ("changes", "field"),
    [({"speed_kmh": 0.0}, "speed_kmh"), ({"rate_hz": -1.0}, "rate_hz"),
     ({"noise_std_mps2": -0.1}, "noise_std_mps2"), ({"initial_state": (0.0,)}, "initial_state"),
     ({"departures": {"damper_ratio": 2.0}}, "departures: expected Departures settings")],
)
def test_invalid_config(changes, field):
    with pytest.raises(ConfigError, match=field):
        SimConfig(**changes)


def test_departures_reach_the_plant_and_the_sensors():
    departures = Departures(damper_ratio=2.0, time_offset_s=0.01, lowpass_hz=30.0)
    sim = Simulation(SimConfig(duration_s=10.0, departures=departures))
    sim.run(1.0)
    assert sim.plant.iterations > 1 and [d.channel for d in sim.plant._delayed] == [1]
    assert sim.sensors._sos is not None
    plain = Simulation(SimConfig(duration_s=10.0))
    assert plain.plant.iterations == 0 and not plain.plant._delayed and plain.sensors._sos is None


def test_oversampling_picks_the_plant_rate():
    assert SimConfig(rate_hz=100.0).oversample == 10
    assert SimConfig(rate_hz=400.0).oversample == 3
    assert SimConfig(rate_hz=1000.0).oversample == 1
