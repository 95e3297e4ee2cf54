"""The estimator node's configuration: from ROS parameter values, and as it travels in bags."""

from __future__ import annotations

import json

import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import LikelihoodConfig, PipelineConfig
from rozyn_estimator.online import EstimatorConfig, OnlineConfig
from rozyn_estimator.vehicle import Vehicle, dump_vehicle


def test_defaults_are_the_nodes():
    config = EstimatorConfig()
    assert (config.online, config.pipeline, config.vehicle) == (OnlineConfig(), PipelineConfig(), Vehicle())
    assert (config.front_topic, config.rear_topic, config.field) == ("accel/front", "accel/rear",
                                                                     "linear_acceleration.z")


def test_from_parameters_by_ros_name():
    values = {
        "window_s": 60, "update_period_s": 2.5, "front_topic": "imu/front", "speed_topic_type": "odometry",
        "pipeline.refine": "none", "pipeline.likelihood.band_hz": [0.8, 12.0], "vehicle.wheelbase_m": 3.0,
        "qos_depth": 10,  # a node option: not part of the configuration
    }
    config = EstimatorConfig.from_parameters(values)
    assert config.online.window_s == 60.0 and config.online.update_period_s == 2.5
    assert config.front_topic == "imu/front" and config.speed_topic_type == "odometry"
    assert config.pipeline.refine == "none" and config.pipeline.likelihood.band_hz == (0.8, 12.0)
    assert config.vehicle.wheelbase_m == 3.0


@pytest.mark.parametrize(("values", "hardware_id"), [
    ({}, "half_car"),
    ({"vehicle.model": "full"}, "full_car"),
    ({"vehicle_file": "config/vehicle_full.yaml"}, "full_car"),
    ({"vehicle.model": "full", "hardware_id": "rig_7"}, "rig_7"),  # an explicit value wins
    ({"hardware_id": "half_car", "vehicle.model": "full"}, "half_car"),
])
def test_the_diagnostics_hardware_id_follows_the_model_unless_set(values, hardware_id):
    config = EstimatorConfig.from_parameters(values)
    assert config.diagnostic_hardware_id == hardware_id
    assert EstimatorConfig.from_json(config.to_json()).diagnostic_hardware_id == hardware_id  # replayed


def test_the_vehicle_file_overrides_the_vehicle_parameters(tmp_path):
    path = tmp_path / "car.yaml"
    path.write_text(dump_vehicle(Vehicle(sprung_mass_kg=1500.0)))
    config = EstimatorConfig.from_parameters({"vehicle_file": str(path), "vehicle.sprung_mass_kg": 900.0})
    assert config.vehicle.sprung_mass_kg == 1500.0


@pytest.mark.parametrize(("values", "words"), [
    ({"window_s": "long"}, "window_s: expected a number in s, got 'long'"),
    ({"window_s": 5000}, r"window_s: must lie in \[1, 3600\] s"),
    ({"update_period_s": 200.0}, "update_period_s: must be <= window_s"),
    ({"pipeline.freq_band_hz": [1.0]}, "pipeline.freq_band_hz: expected 2 numbers"),
    ({"pipeline.stiffness_model": "stiff"}, "pipeline.stiffness_model: must be one of eq2-21, eq2-22"),
    ({"speed_topic_type": "gps"}, "speed_topic_type: must be one of twist, odometry"),
    ({"vehicle.wheelbase_m": -2.0}, "vehicle.wheelbase_m: must be > 0 m"),
    ({"front_axle_x_m": 1e300}, r"front_axle_x_m: must lie in \[-100, 100\] m"),
])
def test_invalid_values_name_the_parameter(values, words):
    with pytest.raises(ConfigError, match=words):
        EstimatorConfig.from_parameters(values)


def test_json_round_trip():
    config = EstimatorConfig(online=OnlineConfig(window_s=90.0), front_topic="/a/front",
                             pipeline=PipelineConfig(likelihood=LikelihoodConfig(taper=0.1)))
    assert EstimatorConfig.from_json(config.to_json()) == config


def test_json_from_another_version():
    data = json.loads(EstimatorConfig().to_json())
    data["future_option"] = 1
    data["online"]["window_s"] = 30
    data["pipeline"]["likelihood"]["new_knob"] = True
    ignored: list[str] = []
    config = EstimatorConfig.from_json(json.dumps(data), ignored)
    assert config.online.window_s == 30.0
    assert ignored == ["estimator configuration.future_option",
                       "estimator configuration.pipeline.likelihood.new_knob"]


@pytest.mark.parametrize(("text", "words"), [
    ("{not json", "not JSON"),
    ('{"online": 3}', "expected a mapping"),
    ('{"online": {"window_s": -1}}', "window_s: must lie in"),
    ('{"pipeline": {"freq_band_hz": 7}}', "pipeline.freq_band_hz: expected a list of numbers"),
])
def test_bad_json_is_a_config_error(text, words):
    with pytest.raises(ConfigError, match=words):
        EstimatorConfig.from_json(text)
