from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle, load_vehicle
from rozyn_estimator.vehicle_full import (
    FullTolerances,
    FullVehicle,
    centreline_half_car,
    dump_full_vehicle,
    full_vehicle_from_mapping,
    load_any_vehicle,
    load_full_vehicle,
)

ROOT = Path(__file__).resolve().parents[1]
CUSTOM = FullVehicle(
    sprung_mass_kg=1450.0, roll_inertia_kgm2=520.0, cog_lateral_m=-0.04, track_front_m=1.58,
    unsprung_mass_kg=(30.0, 31.0, 35.0, 36.0), suspension_stiffness_npm=(25e3, 26e3, 30e3, 31e3),
    anti_roll_stiffness_front_nmprad=18_000.0, sensor_x_m=(0.3, 0.3, 2.5, 2.5),
    sensor_y_m=(0.4, -0.4, 0.4, -0.4),
    tolerances=FullTolerances(track_front_m=0.01, wheelbase_m=0.002),
)


def test_defaults_extend_table_5_1_to_four_corners():
    v = FullVehicle()
    assert centreline_half_car(v) == Vehicle()  # each axle's two corners sum to Table 5-1's value
    assert v.is_symmetric and v.corner_y_m == (0.75, -0.75, 0.75, -0.75)
    assert v.corner_x_m == (0.0, 0.0, 2.8, 2.8) and v.cog_from_rear_axle_m == pytest.approx(1.6)
    assert (v.roll_inertia_kgm2 / v.sprung_mass_kg) ** 0.5 == pytest.approx(0.42 * v.track_front_m, rel=0.01)


def test_centreline_half_car_sums_axles_and_needs_symmetry():
    half = centreline_half_car(CUSTOM.replace(cog_lateral_m=0.0, unsprung_mass_kg=(30.0, 30.0, 35.0, 35.0),
                                              suspension_stiffness_npm=(25e3, 25e3, 30e3, 30e3)))
    assert half.unsprung_mass_front_kg == 60.0 and half.suspension_stiffness_rear_npm == 60e3
    assert half.sensor_front_offset_m == 0.3 and half.sensor_rear_offset_m == pytest.approx(-0.3)
    assert half.tolerances == Tolerances(wheelbase_m=0.002)
    with pytest.raises(ConfigError, match="symmetric"):
        centreline_half_car(CUSTOM)


def test_flat_yaml_roundtrip(tmp_path):
    path = tmp_path / "full.yaml"
    path.write_text(dump_full_vehicle(CUSTOM))
    assert load_full_vehicle(path) == CUSTOM
    assert load_any_vehicle(path) == CUSTOM
    assert full_vehicle_from_mapping(CUSTOM.to_dict()) == CUSTOM
    assert yaml.safe_load(path.read_text())["model"] == "full"


def test_ros_params_file_and_partial_values(tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"vehicle": {
        "model": "full", "roll_inertia_kgm2": 380, "tyre_stiffness_npm": [1e5, 1e5, 1.2e5, 1.2e5]}}}}))
    v = load_full_vehicle(path)
    assert v == FullVehicle(roll_inertia_kgm2=380.0, tyre_stiffness_npm=(1e5, 1e5, 1.2e5, 1.2e5))
    assert isinstance(v.roll_inertia_kgm2, float) and isinstance(v.tyre_stiffness_npm, tuple)


def test_half_car_files_load_as_before(tmp_path):
    repo = ROOT / "config" / "vehicle.yaml"
    assert load_any_vehicle(repo) == load_vehicle(repo) == Vehicle()
    path = tmp_path / "half.yaml"
    path.write_text("model: half\nsprung_mass_kg: 900\n")
    assert load_vehicle(path) == load_any_vehicle(path) == Vehicle(sprung_mass_kg=900.0)
    with pytest.raises(ConfigError, match="a half-car vehicle file"):
        load_full_vehicle(path)


def test_a_full_car_file_is_not_a_half_car(tmp_path):
    path = tmp_path / "full.yaml"
    path.write_text("model: full\nroll_inertia_kgm2: 500\n")
    with pytest.raises(ConfigError, match=r"model: a half-car vehicle has model half.*load_any_vehicle"):
        load_vehicle(path)


@pytest.mark.parametrize(
    ("changes", "words"),
    [({"unsprung_mass_kg": [20, 20, 30]}, "unsprung_mass_kg: expected 4 numbers"),
     ({"tyre_stiffness_npm": [1e5, 1e5, 1e5, -1]}, "tyre_stiffness_npm: must be > 0"),
     ({"suspension_damping_nspm": "soft"}, "suspension_damping_nspm: expected a list of numbers"),
     ({"roll_inertia_kgm2": 0}, "roll_inertia_kgm2: must be > 0"),
     ({"cog_lateral_m": 0.76}, "cog_lateral_m: must lie between the wheels"),
     ({"cog_from_front_axle_m": 3.0}, "cog_from_front_axle_m: must lie between the axles"),
     ({"anti_roll_stiffness_rear_nmprad": -1.0}, "anti_roll_stiffness_rear_nmprad: must be >= 0"),
     ({"sensor_x_m": [1, 1, 1.2, 1.2]}, "sensor_x_m: .*to see pitch"),
     ({"sensor_y_m": [0.1, 0.0, 0.1, 0.0]}, "sensor_y_m: .*to see roll"),
     ({"track_front_m": float("nan")}, "track_front_m: must be finite"),
     ({"model": "quarter"}, "model: must be one of half, full"),
     ({"sprung_mas_kg": 1}, "unknown full-car vehicle parameter.*sprung_mas_kg"),
     ({"unsprung_mass_front_kg": 40}, "unknown full-car vehicle parameter.*unsprung_mass_front_kg"),
     ({"tolerances": {"track_width_m": 0.1}}, "unknown tolerance.*track_width_m"),
     ({"tolerances": {"track_front_m": 2.0}}, "tolerances.track_front_m: must lie in")],
)
def test_invalid_values_name_the_field(tmp_path, changes, words):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({"model": "full", **changes}))
    with pytest.raises(ConfigError, match=words) as info:
        load_any_vehicle(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_full_tolerances_extend_the_half_cars():
    tol = FullTolerances.from_mapping({"track_rear_m": 0.003, "sensor_gain_front": 0.01})
    assert tol.track_rear_m == 0.003 and tol.sensor_gain_front == 0.01 and tol.wheelbase_m == 0.0
    assert tol.half_car() == Tolerances.from_mapping({"sensor_gain_front": 0.01})
    with pytest.raises(ConfigError, match="unknown tolerance"):
        Tolerances.from_mapping({"track_rear_m": 0.003})  # the half car's stay its own


def test_repo_config_is_the_default_full_car():
    assert load_full_vehicle(ROOT / "config" / "vehicle_full.yaml") == FullVehicle()
