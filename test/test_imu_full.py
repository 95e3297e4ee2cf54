"""One IMU on the full car: the sensors block (accel_z, gyro_x, gyro_y), the simulated gyros,
the model's rate channels, the estimate, and the online configuration that reads them."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from bag_helpers import write_imu_bag

from rozyn_estimator.bag import open_bag
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.method.imu import gyro_sign_problem, stage_input
from rozyn_estimator.method.pipeline import estimate
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.online import EstimatorConfig
from rozyn_estimator.online.records import OK, Update, layout_of, update_values
from rozyn_estimator.sensors import sensors_from_mapping
from rozyn_estimator.tools.replay import replay
from rozyn_estimator.tools.replay.feed import ReplayOptions, resolve_config
from rozyn_estimator.vehicle_full import (
    FullTolerances,
    FullVehicle,
    any_vehicle_from_parameters,
    dump_full_vehicle,
    load_any_vehicle,
)
from sim_node.departures import Departures
from sim_node.simulation import SimConfig, Simulation

IMU = {"topic": "/imu/data", "x_m": 1.5, "y_m": 0.2, "channels": ["accel_z", "gyro_x", "gyro_y"]}
BLOCK = {"names": ["imu"], "imu": IMU}
EXACT = FullTolerances(**{k: 0.0 for k in FullTolerances().to_dict()})
SPEED_MPS = 100 / 3.6


def imu_car(exact: bool = True, **changes: float) -> FullVehicle:
    """The default full car with one IMU 0.3 m behind and 0.2 m left of the CoG."""
    base = FullVehicle(**changes)
    return (base.replace(tolerances=EXACT) if exact else base).with_sensors(sensors_from_mapping(BLOCK))


def noisy(y: np.ndarray, share: float, seed: int) -> np.ndarray:
    return y + share * y.std(axis=0) * np.random.default_rng([seed, 5]).standard_normal(y.shape)


# --- the sensors block -----------------------------------------------------------------------
def test_a_full_car_file_with_one_imu(tmp_path):
    path = tmp_path / "car.yaml"
    vehicle = {"model": "full", "sprung_mass_kg": 1100.0, "sensors": BLOCK}
    path.write_text(yaml.safe_dump({"vehicle": vehicle}))
    v = load_any_vehicle(path)
    assert isinstance(v, FullVehicle)
    assert v.channel_names == ("imu.accel_z", "imu.gyro_x", "imu.gyro_y")
    assert v.channel_kinds == ("accel_z", "gyro_x", "gyro_y") and v.channel_late == (False,) * 3
    assert v.sensor_x_m[:3] == (1.5,) * 3 and v.sensor_y_m[:3] == (0.2,) * 3
    assert v.tolerances.sensor_time_offset_s == 0.0  # one IMU, one clock
    again = tmp_path / "again.yaml"
    again.write_text(dump_full_vehicle(v))
    assert load_any_vehicle(again) == v
    params = {"vehicle.model": "full", "vehicle.sensors.names": ["imu"],
              **{f"vehicle.sensors.imu.{k}": value for k, value in IMU.items()}}
    assert any_vehicle_from_parameters(params).channel_names == v.channel_names


@pytest.mark.parametrize(("channels", "says"), [
    (["accel_z"], "neither pitch nor roll"),
    (["accel_z", "gyro_y"], "not roll: add a gyro_x"),
    (["accel_z", "gyro_x"], "not pitch: add a gyro_y"),
    (["gyro_x", "gyro_y"], "not heave"),
])
def test_imu_sets_that_cannot_see_the_body_are_refused_in_one_line(tmp_path, channels, says):
    path = tmp_path / "car.yaml"
    block = {"names": ["i"], "i": {**IMU, "channels": channels}}
    path.write_text(yaml.safe_dump({"model": "full", "sensors": block}))
    with pytest.raises(ConfigError, match=says) as err:
        load_any_vehicle(path)
    assert "\n" not in str(err.value)


def test_three_accelerometers_in_a_block_must_span_the_body():
    line = {"names": ["a", "b", "c"], "a": {"topic": "/a", "x_m": 0.0}, "b": {"topic": "/b", "x_m": 1.4},
            "c": {"topic": "/c", "x_m": 2.8}}
    with pytest.raises(ConfigError, match="not roll"):
        FullVehicle().with_sensors(sensors_from_mapping(line))
    spread = {**line, "c": {"topic": "/c", "x_m": 2.8, "y_m": 0.7}}
    v = FullVehicle().with_sensors(sensors_from_mapping(spread))
    assert v.channel_late == (False, True, True)  # three clocks: the first sensor's and the others'


def test_positions_in_two_places_are_refused(tmp_path):
    path = tmp_path / "car.yaml"
    path.write_text(yaml.safe_dump({"model": "full", "sensor_x_m": [0.1, 0, 2.8, 2.8], "sensors": BLOCK}))
    with pytest.raises(ConfigError, match="not both"):
        load_any_vehicle(path)


# --- the simulated IMU and the model ------------------------------------------------------
def test_the_simulated_gyros_are_the_body_rates_of_the_corner_accelerometers():
    """REP 103: d(gyro_y)/dt = (a_rear - a_front) / L (positive nose down), d(gyro_x)/dt =
    (a_left - a_right) / track; the IMU's accelerometer the body's at its point."""
    corners, imu = FullVehicle(cog_lateral_m=0.05), imu_car(cog_lateral_m=0.05)
    sim = {"model": "full", "seed": 2, "duration_s": 10, "rate_hz": 1000, "include_gravity": False}
    a = Simulation(SimConfig(full_vehicle=corners, **sim)).run(10).accel_mps2
    b = Simulation(SimConfig(full_vehicle=imu, **sim)).run(10).accel_mps2
    L, T = corners.wheelbase_m, corners.track_front_m
    pitch = (a[:, 2] + a[:, 3] - a[:, 0] - a[:, 1]) / (2 * L)
    roll = (a[:, 0] + a[:, 2] - a[:, 1] - a[:, 3]) / (2 * T)
    for column, want in ((2, pitch), (1, roll)):
        got = np.gradient(b[:, column], 1e-3)
        assert np.std(got[5:-5] - want[5:-5]) < 3e-3 * np.std(want)
    heave = a.mean(axis=1)  # the corners' mean: the body's at (L/2, 0)
    at_imu = heave + (1.5 - L / 2) * pitch + 0.2 * roll  # pitch is -phi'': the rear falls as the nose lifts
    assert np.std(b[:, 0] - at_imu) < 1e-3 * np.std(at_imu)
    corners_again, _, _ = stage_input(b, 1000.0, imu, (0, 1, 2))
    assert np.std(corners_again[5:-5] - a[5:-5]) < 5e-3 * np.std(a)  # Rozyn's stage reads the corners


def test_the_rate_channels_are_the_corners_spectrum_through_the_rigid_body():
    """Noise-free, S of the IMU's channels = M S_corners Mᴴ, M mapping four corner accelerations
    to the IMU's accel_z and (by 1/iω) its rates."""
    freq = np.linspace(0.3, 20.0, 120)
    corners, imu = FullVehicle(cog_lateral_m=0.05), imu_car(cog_lateral_m=0.05)
    s = {}
    for name, v, k in (("corners", corners, (0, 1, 2, 3)), ("imu", imu, (0, 1, 2))):
        model = VehicleSpectrum(v, k, freq, 100.0, SPEED_MPS, aliases=0)
        theta = model.theta(np.array([1000.0, 400.0, 2000.0, 1.2, 0.05]), 1e-6, np.full(len(k), 1e-30))
        s[name], _ = model.spectrum(theta, derivatives=False)
    L, T, w = 2.8, 1.5, 2 * np.pi * freq
    B = np.column_stack([np.ones(4), -np.array(corners.corner_x_m), np.array(corners.corner_y_m)])
    body = np.linalg.pinv(B)  # corners -> (z0'', phi'', theta'')
    rows = np.array([[1.0, -1.5, 0.2], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]) @ body
    M = np.repeat(rows[None], freq.size, axis=0).astype(complex)
    M[:, 1:] /= (1j * w)[:, None, None]
    want = M @ s["corners"] @ M.conj().transpose(0, 2, 1)
    np.testing.assert_allclose(s["imu"], want, rtol=1e-6, atol=1e-12 * np.abs(want).max())
    del L, T


# --- estimates ------------------------------------------------------------------------------
def test_one_imu_estimates_the_full_car_as_four_accelerometers_do():
    """10 % noise per channel, 120 s at 100 km/h, exact vehicle: covered, and within 2x the
    four corners' std on the same road."""
    truth = np.array([1000.0, 400.0, 2000.0, 1.2, 0.0])
    got = {}
    for name, v in (("imu", imu_car()), ("corners", FullVehicle(tolerances=EXACT))):
        sim = SimConfig(model="full", full_vehicle=v, seed=3, duration_s=120, speed_kmh=100)
        y = noisy(Simulation(sim).run(120).accel_mps2, 0.1, 3)
        got[name] = e = estimate(y, 100.0, v, PipelineConfig(), speed_mps=SPEED_MPS)
        assert e.ok and e.stage == "likelihood", e.reason
        assert np.all(np.abs(e.params - truth) < 4 * e.std), (name, e.params, e.std)
        assert not [n for n in e.notes if "model check" in n], e.notes
    assert np.all(got["imu"].std < 2 * got["corners"].std)
    assert got["imu"].rozyn is not None and got["imu"].rozyn.ok  # the stage from the equivalent corners
    assert got["imu"].sensors == ("imu.accel_z", "imu.gyro_x", "imu.gyro_y")


def test_the_online_configuration_reads_the_imu_topic():
    params = {"vehicle.model": "full", "vehicle.sensors.names": ["imu"],
              **{f"vehicle.sensors.imu.{k}": value for k, value in IMU.items()}}
    config = EstimatorConfig.from_parameters(params)
    assert config.sensors == (("imu.accel_z", "/imu/data"), ("imu.gyro_x", "/imu/data"),
                              ("imu.gyro_y", "/imu/data"))
    assert config.fields == ("linear_acceleration.z", "angular_velocity.x", "angular_velocity.y")
    assert config.layout.channels == ("imu.accel_z", "imu.gyro_x", "imu.gyro_y") and config.layout.full
    assert EstimatorConfig.from_json(config.to_json()) == config
    with pytest.raises(ConfigError, match="channels are"):
        layout_of(config.full_vehicle, ["front_left", "front_right", "rear_left"])


def test_a_gyro_with_the_wrong_sign_is_named_not_fitted():
    """A gyro read with the sign opposite to REP 103's is refused with its name (the roll gyro
    where the IMU sits off the centreline: there its accelerometer sees the roll); the right signs
    pass, also with the vehicle file's values 20 % off."""
    v = imu_car()
    y = noisy(Simulation(SimConfig(model="full", full_vehicle=v, seed=2, duration_s=120,
                                   speed_kmh=30)).run(120).accel_mps2, 0.1, 2)
    for column, says in ((2, "imu.gyro_y reads the pitch rate"), (1, "imu.gyro_x reads the roll rate")):
        flip = np.ones(3)
        flip[column] = -1.0
        e = estimate(y * flip, 100.0, v, PipelineConfig(), speed_mps=30 / 3.6)
        assert not e.ok and says in e.reason and "REP 103" in e.reason, e.reason
    told = v.replace(sprung_mass_kg=1200.0, roll_inertia_kgm2=480.0, pitch_inertia_kgm2=1600.0,
                     cog_from_front_axle_m=1.4)
    assert gyro_sign_problem(y, 100.0, told, 30 / 3.6) is None


def test_a_bag_of_one_imu_topic_replays_with_the_full_car_file(tmp_path):
    """``rozyn replay BAG --vehicle FILE``: one /imu/data topic, its three channels."""
    v = imu_car()
    path = tmp_path / "car.yaml"
    path.write_text(dump_full_vehicle(v))
    y = noisy(Simulation(SimConfig(model="full", full_vehicle=v, seed=4, duration_s=125)).run(125).accel_mps2,
              0.05, 4)
    write_imu_bag(tmp_path / "bag", y[:, 0], y[:, 1], y[:, 2])
    with open_bag(tmp_path / "bag") as reader:
        options = ReplayOptions(vehicle=str(path), speed_mps=SPEED_MPS, window_s=120.0)
        config, _ = resolve_config(reader, options)
    assert config.sensors == (("imu.accel_z", "/imu/data"), ("imu.gyro_x", "/imu/data"),
                              ("imu.gyro_y", "/imu/data"))
    result = replay(tmp_path / "bag", config)
    published = [u.update for u in result.updates if u.update.published]
    assert published and result.accel_messages == y.shape[0]
    last = published[-1].estimate
    truth = np.array([1000.0, 400.0, 2000.0, 1.2, 0.0])
    assert np.all(np.abs(last.params - truth) < 4 * last.std), last.params


# --- an IMU mounted turned ------------------------------------------------------------------
def test_a_turned_imu_mixes_its_gyros_in_the_simulator():
    """Turned by a about z, gyro_x reads cos a roll rate + sin a pitch rate, gyro_y -sin a roll
    rate + cos a pitch rate (REP 103); the accelerometer is as before. Only a full car's IMU
    with both gyros can turn."""
    v, a = imu_car(), 0.1
    sim = {"model": "full", "full_vehicle": v, "seed": 6, "duration_s": 5}
    plain = Simulation(SimConfig(**sim)).run(5).accel_mps2
    turn = Departures(gyro_yaw_misalignment_rad=a)
    turned = Simulation(SimConfig(**sim, departures=turn)).run(5).accel_mps2
    c, s = np.cos(a), np.sin(a)
    np.testing.assert_allclose(turned[:, 0], plain[:, 0])
    np.testing.assert_allclose(turned[:, 1], c * plain[:, 1] + s * plain[:, 2], atol=1e-12)
    np.testing.assert_allclose(turned[:, 2], -s * plain[:, 1] + c * plain[:, 2], atol=1e-12)
    with pytest.raises(ConfigError, match="gyro_x and gyro_y"):
        Simulation(SimConfig(departures=Departures(gyro_yaw_misalignment_rad=a)))


def test_a_turned_imu_is_calibrated_not_mistaken_for_the_cog():
    """2° off: told exactly (no tolerance for the turn) the lateral CoG reads many std off and
    the model check objects; with the default 0.57° tolerance the fit calibrates the turn from
    the data and covers the truth."""
    truth = np.array([1000.0, 400.0, 2000.0, 1.2, 0.0])
    v = imu_car(exact=False)
    sim = SimConfig(model="full", full_vehicle=v, seed=5, duration_s=120,
                    departures=Departures(gyro_yaw_misalignment_rad=np.radians(2.0)))
    y = noisy(Simulation(sim).run(120).accel_mps2, 0.1, 5)
    e = estimate(y, 100.0, v, PipelineConfig(), speed_mps=SPEED_MPS)
    assert e.ok and np.all(np.abs(e.params - truth) < 3 * e.std), (e.params, e.std)
    turn = next(c for c in e.budget.calibration if c.name == "gyro_turn_imu.gyro_y_rad")
    assert abs(np.degrees(turn.estimate) - 2.0) < 3 * np.degrees(turn.std) and turn.identified
    values = update_values(Update(1, OK, "ok", e), layout_of(v))  # as the node's diagnostics say it
    assert values["calibrated gyro_turn_imu.gyro_y_rad"].endswith("identified by the data)")
    assert all(values[f"{name}_budget"] for name in FULL_PARAM_NAMES)
    # what varies between windows (the load change's test counts it): part of the calibrated values'
    calibrated = sum(np.outer(c, c) for key, c in e.budget.contributions.items() if key in e.budget.varying)
    varying = e.budget.between_windows - e.budget.statistical
    assert 0 < np.trace(varying) <= np.trace(calibrated) * (1 + 1e-9)
    told = imu_car()  # every tolerance 0: the turn is not fitted
    blind = estimate(y, 100.0, told, PipelineConfig(), speed_mps=SPEED_MPS)
    assert abs(blind.params[4] - truth[4]) > 5 * blind.std[4]
    assert any("model check" in n for n in blind.notes), blind.notes
