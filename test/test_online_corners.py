"""The online estimator on the full car's corner accelerometers (no DDS): the same window,
pairing, reset and schedule logic as the half car's on three or four channels, each update
run by ``estimate`` on the right columns; its configuration as it travels in bags."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.method.pipeline import Estimate, estimate
from rozyn_estimator.online import (
    ERROR,
    HALF_LAYOUT,
    NS,
    OK,
    EstimatorConfig,
    OnlineConfig,
    OnlineEstimator,
    align_channels,
    layout_of,
)
from rozyn_estimator.online import update as update_module
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import CORNERS, FullVehicle, load_full_vehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

PIPELINE = PipelineConfig(refine="none")  # Rozyn's stage: fast, and what these tests check is the feeding
CONFIG = OnlineConfig(window_s=30.0, update_period_s=10.0, speed_mps=100 / 3.6)


@pytest.fixture(scope="module")
def block():
    """60 s of the full car at 100 Hz (Gaussian ISO A, a little noise), columns FL, FR, RL, RR."""
    cfg = SimConfig(model="full", duration_s=60.0, seed=4, road=RoadSpec(amplitudes="gaussian"),
                    noise_std_mps2=0.02)
    return Simulation(cfg).run(60.0)


def _feed(est: OnlineEstimator, accel: np.ndarray, t_ns: np.ndarray) -> list:
    """Every sample, channel by channel at each instant (arrival order), one by one; the updates."""
    updates = []
    for i, t in enumerate(t_ns.tolist()):
        for c in range(accel.shape[1]):
            updates += [est.compute(job) for job in est.add(c, t, float(accel[i, c]))]
    return updates


def test_four_corners_update_when_all_are_there_with_estimate_on_the_window(block):
    t = np.arange(block.t_s.size, dtype=np.int64) * NS // 100
    est = OnlineEstimator(FullVehicle(), CONFIG, PIPELINE)
    assert est.layout.channels == CORNERS and est.names == CORNERS and est.layout.full
    updates = _feed(est, block.accel_mps2, t)
    assert [u.stamp_ns // NS for u in updates] == [10, 20, 30, 40, 50]
    assert [u.published for u in updates] == [False, False, True, True, True]
    last = updates[-1]
    assert last.level == OK and isinstance(last.estimate, Estimate)
    assert last.params.shape == (5,) and last.covariance.shape == (5, 5)
    # the window the update used: the last 30 s of the four columns, estimate on them
    window = block.accel_mps2[(t > 20 * NS) & (t <= 50 * NS)]
    direct = estimate(window, 100.0, FullVehicle(), PIPELINE, speed_mps=100 / 3.6)
    np.testing.assert_allclose(last.params, direct.params, rtol=1e-9)  # BLAS order aside: the same
    np.testing.assert_allclose(last.covariance, direct.covariance, rtol=1e-7)
    values = est.report().values
    for corner in CORNERS:
        assert values[f"samples_{corner}"] == "6000" and values[f"missing_{corner}"] == "0"
    assert "samples_front" not in values
    assert {f"{n}_std" for n in FULL_PARAM_NAMES} <= set(values) and "mode3_freq_hz" in values
    assert float(values["roll_inertia_kgm2"]) == pytest.approx(last.params[1], rel=1e-5)


@pytest.mark.parametrize("missing", CORNERS)
def test_three_corners_run_estimate_on_their_own_columns(block, missing):
    """Any three: channel k is the k-th corner named, and the update says which corner each column is."""
    corners = tuple(c for c in CORNERS if c != missing)
    columns = [CORNERS.index(c) for c in corners]
    t = np.arange(block.t_s.size, dtype=np.int64) * NS // 100
    est = OnlineEstimator(FullVehicle(), CONFIG, PIPELINE, channels=corners)
    jobs = est.add_batch(np.tile(np.arange(3), t.size), np.repeat(t, 3), block.accel_mps2[:, columns].ravel())
    update = est.compute(jobs[-1][0])
    window = block.accel_mps2[(t > 20 * NS) & (t <= 50 * NS)][:, columns]
    direct = estimate(window, 100.0, FullVehicle(), PIPELINE, speed_mps=100 / 3.6, sensors=corners)
    assert update.published and update.estimate.sensors == corners
    np.testing.assert_allclose(update.params, direct.params, rtol=1e-7)  # BLAS order aside: the same
    assert f"samples_{missing}" not in est.report().values


def test_a_batch_gives_the_updates_of_one_by_one(block):
    t = np.arange(block.t_s.size, dtype=np.int64) * NS // 100
    one = _feed(OnlineEstimator(FullVehicle(), CONFIG, PIPELINE), block.accel_mps2, t)
    est = OnlineEstimator(FullVehicle(), CONFIG, PIPELINE)
    jobs = est.add_batch(np.tile(np.arange(4), t.size), np.repeat(t, 4), block.accel_mps2.ravel())
    batch = [est.compute(job) for job, _ in jobs]
    assert [j for _, j in jobs] == [4 * (1000 * k - 0) + 3 for k in range(1, 6)]  # the rear right's sample
    for a, b in zip(one, batch, strict=True):
        assert (a.stamp_ns, a.level, a.message) == (b.stamp_ns, b.level, b.message)
        if a.published:
            np.testing.assert_array_equal(a.params, b.params)


def test_the_slowest_corner_holds_the_schedule_and_a_gap_on_one_resets(block):
    t = np.arange(block.t_s.size, dtype=np.int64) * NS // 100
    est = OnlineEstimator(FullVehicle(), CONFIG, PIPELINE, names=("fl", "fr", "rl", "rr"))
    for c in range(3):  # three corners 15 s ahead: no update falls due while the fourth is silent
        for i in range(1500):
            assert not est.add(c, int(t[i]), float(block.accel_mps2[i, c]))
    health = est.health()
    assert "waiting for rr: no message yet" in health.message
    due = [job.due_ns for i in range(1500) for job in est.add(3, int(t[i]), float(block.accel_mps2[i, 3]))]
    assert due == [10 * NS]  # the fourth catches up: the update due at 10 s falls due with it
    est.add(2, int(t[1500] + NS), 0.0)  # a 1 s gap on the rear left resets the window
    assert est.resets == 1 and "window reset: gap of 1.010 s on rl" in est.report().message


def test_bad_input_is_dropped_and_counted_per_corner():
    est = OnlineEstimator(FullVehicle(), CONFIG, PIPELINE, channels=CORNERS[:3])
    est.add(1, 0, 9.81)
    est.add(1, 0, 9.81)
    est.add(2, 10_000_000, float("nan"))
    est.drop(0, "undecodable message", 2)
    est.drop(3, "undecodable message")  # one past the channels: the speed
    assert est.dropped == {"front_right: duplicate stamp": 1, "rear_left: non-finite value": 1,
                           "front_left: undecodable message": 2, "speed: undecodable message": 1}


def test_a_non_positive_inertia_is_never_published_a_negative_lateral_cog_is(block, monkeypatch):
    t = np.arange(block.t_s.size, dtype=np.int64) * NS // 100
    real = update_module.estimate

    def with_params(params):
        def fake(*args, **kwargs):
            est = real(*args, **kwargs)
            return Estimate("ok", params=np.array(params), covariance=est.covariance, modes=est.modes,
                            names=est.names)
        return fake

    n = 4000  # 40 s: the update due at 30 s has a full window
    for params, level in (([1000.0, 400.0, 2000.0, 1.2, -0.05], OK), ([1e3, -400.0, 2e3, 1.2, 0.0], ERROR)):
        monkeypatch.setattr(update_module, "estimate", with_params(params))
        est = OnlineEstimator(FullVehicle(), CONFIG, PIPELINE)
        jobs = est.add_batch(np.tile(np.arange(4), n), np.repeat(t[:n], 4), block.accel_mps2[:n].ravel())
        update = est.compute(jobs[-1][0])
        assert update.level == level and update.published == (level == OK), update.message


def test_layouts_and_their_refusals():
    assert layout_of(Vehicle()) == HALF_LAYOUT and layout_of(Vehicle(), ("front", "rear")) == HALF_LAYOUT
    assert layout_of(FullVehicle()).params == FULL_PARAM_NAMES and layout_of(FullVehicle()).modes == 3
    for vehicle, channels, words in (
        (Vehicle(), CORNERS, "a half car's channels are front and rear"),
        (FullVehicle(), CORNERS[:2], "three or four distinct corners"),
        (FullVehicle(), ("front_left", "front_left", "rear_left"), "three or four distinct corners"),
        (FullVehicle(), ("front", "rear", "rear_left"), "three or four distinct corners"),
    ):
        with pytest.raises(ConfigError, match=words):
            OnlineEstimator(vehicle, channels=channels)
    with pytest.raises(ConfigError, match="one name per channel"):
        OnlineEstimator(FullVehicle(), names=("a", "b"))
    with pytest.raises(ConfigError, match="cannot change while running"):
        OnlineEstimator(FullVehicle()).reconfigure(Vehicle(), OnlineConfig(), PipelineConfig())


def test_aligned_corners_are_paired_others_resampled():
    t = np.arange(1000, dtype=np.int64) * NS // 100
    v = np.sin(np.arange(1000) / 7.0)
    grid, y, fs = align_channels([(t, v), (t, 2 * v), (t, 3 * v), (t, 4 * v)], OnlineConfig())
    assert fs == 100.0 and np.array_equal(grid, t)
    assert np.array_equal(y, np.column_stack([v, 2 * v, 3 * v, 4 * v]))
    grid, y, fs = align_channels([(t, v), (t + 5_000_000, v), (t, v)], OnlineConfig())  # one 5 ms late
    assert y.shape[1] == 3 and grid[0] >= 5_000_000 and fs == pytest.approx(100.0)
    apart = align_channels([(t[:400], v[:400]), (t[500:], v[500:]), (t, v)], OnlineConfig())
    assert apart == "the accelerometers' samples do not overlap in time"


def test_the_full_car_configuration_from_parameters_and_through_json(tmp_path):
    full_file = "config/vehicle_full.yaml"
    config = EstimatorConfig.from_parameters({"vehicle_file": full_file, "rear_right_topic": ""})
    assert config.model == "full" and config.full_vehicle == load_full_vehicle(full_file)
    assert config.sensors == (("front_left", "accel/front_left"), ("front_right", "accel/front_right"),
                              ("rear_left", "accel/rear_left"))
    again = EstimatorConfig.from_json(config.to_json())
    assert again == config and again.layout.channels == ("front_left", "front_right", "rear_left")
    by_parameters = EstimatorConfig.from_parameters(
        {"vehicle.model": "full", "vehicle.roll_inertia_kgm2": 500.0,
         "vehicle.unsprung_mass_kg": [20, 21, 32, 33]})
    assert by_parameters.full_vehicle == FullVehicle(roll_inertia_kgm2=500.0,
                                                     unsprung_mass_kg=(20, 21, 32, 33))
    half = EstimatorConfig()
    assert "full_vehicle" not in json.loads(half.to_json()) and half.sensors[0] == ("front", "accel/front")
    assert EstimatorConfig.from_json(half.to_json()) == half
    for values, words in (
        ({"vehicle.model": "full", "front_left_topic": "", "rear_left_topic": ""}, "at least three of"),
        ({"vehicle.model": "full", "vehicle_file": "config/vehicle.yaml"}, "is a half car's"),
        ({"vehicle.model": "quarter"}, "vehicle.model: must be one of half, full"),
        ({"vehicle.model": "full", "vehicle.roll_inertia_kgm2": -1.0}, "roll_inertia_kgm2: must be > 0"),
    ):
        with pytest.raises(ConfigError, match=words):
            EstimatorConfig.from_parameters(values)
    bad = json.loads(config.to_json())
    bad["full_vehicle"]["cog_lateral_m"] = 5.0
    with pytest.raises(ConfigError, match="cog_lateral_m"):
        EstimatorConfig.from_json(json.dumps(bad))
