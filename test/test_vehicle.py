from __future__ import annotations

import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.vehicle import Vehicle, dump_vehicle, load_vehicle, vehicle_from_mapping


def test_defaults_are_table_5_1():
    v = Vehicle()
    assert (v.sprung_mass_kg, v.pitch_inertia_kgm2, v.cog_from_front_axle_m) == (1000.0, 2000.0, 1.2)
    assert (v.unsprung_mass_front_kg, v.unsprung_mass_rear_kg) == (40.0, 65.0)
    assert (v.suspension_stiffness_front_npm, v.suspension_stiffness_rear_npm) == (45_000.0, 80_000.0)
    assert (v.suspension_damping_front_nspm, v.suspension_damping_rear_nspm) == (2800.0, 3500.0)
    assert v.tyre_stiffness_front_npm == v.tyre_stiffness_rear_npm == 200_000.0
    assert v.tyre_damping_front_nspm == 50.0
    assert v.wheelbase_m == 2.8
    assert v.cog_from_rear_axle_m == pytest.approx(1.6)
    assert v.sensor_x_m == (0.0, 2.8)


def test_flat_yaml_roundtrip(tmp_path):
    v = Vehicle(sprung_mass_kg=1500.0, wheelbase_m=3.1, cog_from_front_axle_m=1.4)
    path = tmp_path / "v.yaml"
    path.write_text(dump_vehicle(v))
    assert load_vehicle(path) == v


def test_ros_params_yaml(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text(
        "estimator_node:\n  ros__parameters:\n    vehicle:\n      wheelbase_m: 3.0\n"
        "      cog_from_front_axle_m: 1.3\n    window_s: 120.0\n"
    )
    v = load_vehicle(path)
    assert v.wheelbase_m == 3.0 and v.cog_from_front_axle_m == 1.3
    assert v.sprung_mass_kg == 1000.0


def test_a_vehicle_key_with_nothing_under_it_is_the_defaults(tmp_path):
    path = tmp_path / "v.yaml"
    path.write_text("vehicle:\n  # every value its default\n")
    assert load_vehicle(path) == Vehicle()


def test_repo_config_loads():
    from pathlib import Path

    v = load_vehicle(Path(__file__).parents[1] / "config" / "vehicle.yaml")
    assert v == Vehicle()


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("sprung_mass_kg", -5.0, "sprung_mass_kg"),
        ("suspension_stiffness_rear_npm", 0.0, "suspension_stiffness_rear_npm"),
        ("tyre_damping_front_nspm", -1.0, "tyre_damping_front_nspm"),
        ("cog_from_front_axle_m", 3.0, "between the axles"),
        ("cog_from_front_axle_m", 0.0, "cog_from_front_axle_m"),
        ("pitch_inertia_kgm2", float("nan"), "finite"),
        ("sensor_front_offset_m", 2.5, "quarter wheelbase"),
    ],
)
def test_invalid_values_name_the_field(field, value, words):
    with pytest.raises(ConfigError, match=words):
        Vehicle(**{field: value})


def test_unknown_and_non_numeric_keys(tmp_path):
    with pytest.raises(ConfigError, match="sprung_mas_kg"):
        vehicle_from_mapping({"sprung_mas_kg": 900})
    path = tmp_path / "bad.yaml"
    path.write_text("wheelbase_m: long\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml.*wheelbase_m"):
        load_vehicle(path)


def test_missing_and_broken_files(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_vehicle(tmp_path / "nope.yaml")
    path = tmp_path / "broken.yaml"
    path.write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_vehicle(path)


def test_tolerances_defaults_file_mapping_and_parameters(tmp_path):
    from rozyn_estimator.tolerances import KEYS, Tolerances
    from rozyn_estimator.vehicle import vehicle_from_parameters

    assert Vehicle().tolerances == Tolerances() and Tolerances().any  # the data-sheet defaults
    assert set(KEYS) == {
        *(f"{q}_{axle}_{u}" for q, u in (("suspension_stiffness", "npm"), ("suspension_damping", "nspm"),
                                         ("tyre_stiffness", "npm"), ("tyre_damping", "nspm"))
          for axle in ("front", "rear")),
        "unsprung_mass_front_kg", "unsprung_mass_rear_kg", "wheelbase_m", "sensor_front_offset_m",
        "sensor_rear_offset_m", "sensor_gain_front", "sensor_gain_rear", "sensor_time_offset_s",
        "cog_height_m", "wheel_centre_height_m"}
    path = tmp_path / "car.yaml"
    path.write_text("wheelbase_m: 2.9\ntolerances: {tyre_stiffness_front_npm: 0.1}\n")
    listed = load_vehicle(path).tolerances
    assert listed.tyre_stiffness_front_npm == 0.1 and listed.tyre_stiffness_rear_npm == 0.0  # the rest: exact
    path.write_text("tolerances: {}\n")
    assert load_vehicle(path).tolerances == Tolerances.none() and not Tolerances.none().any
    path.write_text("tolerances: {tyre_stifness_front_npm: 0.1}\n")
    with pytest.raises(ConfigError, match=r"unknown tolerance.*tyre_stifness_front_npm"):
        load_vehicle(path)
    path.write_text("tolerances: {sensor_gain_front: -0.1}\n")
    with pytest.raises(ConfigError, match=r"vehicle.tolerances.sensor_gain_front: must lie in \[0, 1\]"):
        load_vehicle(path)
    # as ROS parameters each overrides its default
    v = vehicle_from_parameters({"vehicle.tolerances.sensor_time_offset_s": 0.005,
                                 "vehicle.wheelbase_m": 3.0})
    assert v.tolerances == Tolerances(sensor_time_offset_s=0.005) and v.wheelbase_m == 3.0
    assert vehicle_from_mapping(Vehicle().to_dict()) == Vehicle()  # round trip


def test_a_bag_recorded_before_tolerances_replays_without_them():
    import json

    from rozyn_estimator.online import EstimatorConfig
    from rozyn_estimator.tolerances import Tolerances

    data = json.loads(EstimatorConfig().to_json())
    del data["vehicle"]["tolerances"]
    assert EstimatorConfig.from_json(json.dumps(data)).vehicle.tolerances == Tolerances.none()
