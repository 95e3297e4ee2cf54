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
