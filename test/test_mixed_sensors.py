"""Mixed sensor sets, both cars: an IMU with two accelerometers, three accelerometers. One
likelihood over all their channels: each set is at least as precise as the best of its parts on
the same road, and a bag of their topics replays through the vehicle file."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from bag_helpers import IMU, NS, imu_message

from rozyn_estimator.bag import SENSOR_QOS, BagWriter, default_typestore, open_bag
from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.method.pipeline import estimate
from rozyn_estimator.online import EstimatorConfig
from rozyn_estimator.sensors import sensors_from_mapping
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.tools.replay import replay
from rozyn_estimator.tools.replay.feed import ReplayOptions, resolve_config
from rozyn_estimator.vehicle import Vehicle, dump_vehicle
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle, load_any_vehicle
from sim_node.simulation import SimConfig, Simulation

SPEED_MPS = 100 / 3.6
# a std is taken at its own fit's values (an inertia's scales with it): on one road a set with more
# channels may read up to this share above its part where the added channels tell that parameter nothing
AT_ITS_FIT = 1.02
IMU_SENSOR = {"topic": "/imu/data", "x_m": 1.5, "y_m": 0.0, "channels": ["accel_z", "gyro_y"]}
HALF_MIXED = {"names": ["imu", "front", "rear"], "imu": IMU_SENSOR,
              "front": {"topic": "/accel/front", "x_m": 0.0}, "rear": {"topic": "/accel/rear", "x_m": 2.8}}
FULL_IMU = {"topic": "/imu/data", "x_m": 1.5, "y_m": 0.2, "channels": ["accel_z", "gyro_x", "gyro_y"]}


def _half(block: dict | None) -> Vehicle:
    exact = Vehicle(tolerances=Tolerances.none())
    return exact if block is None else exact.with_sensors(sensors_from_mapping(block))


def _full(block: dict) -> FullVehicle:
    return FullVehicle(tolerances=FullTolerances.none()).with_sensors(sensors_from_mapping(block))


def _estimate(vehicle: Vehicle | FullVehicle, seed: int):
    """The exact vehicle's estimate on road ``seed`` (Gaussian ISO A, 100 km/h, 120 s), 10 % white
    noise of each channel's rms."""
    model = "full" if vehicle.ROLLS else "half"
    sim = SimConfig(model=model, **{"full_vehicle" if vehicle.ROLLS else "vehicle": vehicle}, seed=seed,
                    duration_s=120)
    clean = Simulation(sim).run(120).accel_mps2
    y = clean + 0.1 * clean.std(axis=0) * np.random.default_rng([seed, 9]).standard_normal(clean.shape)
    e = estimate(y, 100.0, vehicle, PipelineConfig(), speed_mps=SPEED_MPS)
    assert e.ok and e.stage == "likelihood", e.reason
    truth = vehicle.body_values
    assert np.all(np.abs(e.params - truth) < 4 * e.std), (vehicle.channel_names, e.params, e.std)
    return e


def test_the_half_cars_block_takes_any_number_of_channels(tmp_path):
    v = _half(HALF_MIXED)
    assert v.channel_names == ("front.accel_z", "imu.accel_z", "rear.accel_z", "imu.gyro_y")
    assert v.sensor_x_m == (0.0, 1.5, 2.8, 1.5) and v.channel_kinds[-1] == "gyro_y"
    assert v.channel_late == (False, True, True, True)  # the first sensor's clock is the reference
    path = tmp_path / "car.yaml"
    path.write_text(dump_vehicle(v))
    assert load_any_vehicle(path) == v
    config = EstimatorConfig(vehicle=v)
    assert EstimatorConfig.from_json(config.to_json()) == config  # as the node records it


@pytest.mark.parametrize("seed", [3])
def test_an_imu_with_two_accelerometers_beats_each_on_the_half_car(seed):
    sets = (HALF_MIXED, {"names": ["imu"], "imu": IMU_SENSOR}, None)
    mixed, imu, axles = (_estimate(_half(block), seed) for block in sets)
    best = np.minimum(imu.std, axles.std)
    assert np.all(mixed.std <= AT_ITS_FIT * best), (mixed.std, imu.std, axles.std)


def test_a_third_accelerometer_adds_to_two_on_the_half_car():
    three = {"names": ["front", "mid", "rear"], "front": {"topic": "/f", "x_m": 0.0},
             "mid": {"topic": "/m", "x_m": 1.4}, "rear": {"topic": "/r", "x_m": 2.8}}
    assert np.all(_estimate(_half(three), 5).std <= AT_ITS_FIT * _estimate(_half(None), 5).std)


def test_an_imu_with_two_accelerometers_beats_the_imu_on_the_full_car():
    """Five channels: more than the four corners the full car was built for."""
    mixed = {"names": ["imu", "front", "rear"], "imu": FULL_IMU,
             "front": {"topic": "/accel/front", "x_m": 0.0, "y_m": 0.0},
             "rear": {"topic": "/accel/rear", "x_m": 2.8, "y_m": 0.0}}
    v = _full(mixed)
    assert len(v.channel_names) == 5 and len(v.sensor_x_m) == 5
    imu = _full({"names": ["imu"], "imu": FULL_IMU})
    assert np.all(_estimate(v, 2).std <= AT_ITS_FIT * _estimate(imu, 2).std)


def test_a_bag_of_three_sensors_replays_with_the_vehicle_file(tmp_path):
    """``rozyn replay BAG --vehicle FILE`` with an IMU and two accelerometers on their own topics."""
    v = _half(HALF_MIXED)
    path = tmp_path / "car.yaml"
    exact = Tolerances.none().to_dict()
    path.write_text(yaml.safe_dump({"vehicle": {"tolerances": exact, "sensors": HALF_MIXED}}))
    y = Simulation(SimConfig(vehicle=v, seed=4, duration_s=125)).run(125).accel_mps2
    y = y + 0.05 * y.std(axis=0) * np.random.default_rng(4).standard_normal(y.shape)
    store = default_typestore()
    with BagWriter(tmp_path / "bag") as writer:
        topics = {name: writer.add_topic(HALF_MIXED[name]["topic"], IMU, [SENSOR_QOS])
                  for name in HALF_MIXED["names"]}
        for k, (front, imu_z, rear, gyro) in enumerate(y.tolist()):
            ns = NS + k * NS // 100
            for name, z, rates in (("imu", imu_z, (0.0, gyro)), ("front", front, None), ("rear", rear, None)):
                msg = imu_message(store, ns, z, f"{name}_link", rates)
                writer.write(topics[name], ns, bytes(store.serialize_cdr(msg, IMU)))
    with open_bag(tmp_path / "bag") as reader:
        options = ReplayOptions(vehicle=str(path), speed_mps=SPEED_MPS, window_s=120.0)
        config, _ = resolve_config(reader, options)
    assert dict(config.sensors) == {"front.accel_z": "/accel/front", "imu.accel_z": "/imu/data",
                                    "rear.accel_z": "/accel/rear", "imu.gyro_y": "/imu/data"}
    published = [u.update for u in replay(tmp_path / "bag", config).updates if u.update.published]
    assert published
    last = published[-1].estimate
    assert np.all(np.abs(last.params - v.body_values) < 4 * last.std), (last.params, last.std)
