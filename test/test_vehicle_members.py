"""Both vehicle files describe themselves to the one vehicle model through the same members:
``corners``, ``ROLLS``, ``body_values``, ``FRONT_SLOTS``, ``CORNER_FIELDS`` and ``SENSOR_FIELDS``."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.body_model import corner_count, dof
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method.body_parameters import BodyParameters
from rozyn_estimator.method.vehicle_fit.uncertainty.moves import shifted_sensor, values_of, vehicle_moves
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle, centreline_half_car

BARS = FullVehicle(anti_roll_stiffness_front_nmprad=18_000.0, track_rear_m=1.6)


def test_the_half_car_is_the_full_cars_axles_lumped():
    full, half = FullVehicle(), centreline_half_car(FullVehicle())
    a, b = full.corners, half.corners
    for name in ("unsprung_mass_kg", "suspension_stiffness_npm", "suspension_damping_nspm",
                 "tyre_stiffness_npm", "tyre_damping_nspm"):
        lumped = getattr(a, name).reshape(2, 2).sum(axis=1)
        np.testing.assert_allclose(getattr(b, name), lumped, err_msg=name)
    np.testing.assert_allclose(b.x_m, a.x_m[::2])
    assert (corner_count(half), dof(half), corner_count(full), dof(full)) == (2, 4, 4, 7)


def test_a_bar_is_a_spring_between_its_axles_corners():
    bars = BARS.corners.bars_npm
    spring = 18_000.0 / 1.5**2
    np.testing.assert_allclose(bars[:2, :2], spring * np.array([[1.0, -1.0], [-1.0, 1.0]]))
    assert not bars[2:].any() and not bars[:, 2:].any()
    assert Vehicle().corners.bars == () and not Vehicle().corners.bars_npm.any()


@pytest.mark.parametrize("vehicle", [Vehicle(), BARS], ids=["half", "full"])
def test_the_corner_values_follow_the_corner_fields(vehicle):
    values = values_of(vehicle)
    n = corner_count(vehicle)
    assert values.size == 5 * n + len(vehicle.corners.bars)
    if vehicle.ROLLS:  # five per-corner tuples, then the bars
        expected = np.concatenate([np.ravel(getattr(vehicle, f)) for f in vehicle.CORNER_FIELDS])
    else:  # each quantity front then rear
        expected = np.array([getattr(vehicle, f) for f in vehicle.CORNER_FIELDS])
    np.testing.assert_array_equal(values, expected)


@pytest.mark.parametrize("vehicle", [Vehicle(cog_from_front_axle_m=1.3), BARS.replace(cog_lateral_m=0.04)],
                         ids=["half", "full"])
def test_the_body_values_are_in_the_likelihoods_order(vehicle):
    body = BodyParameters(vehicle.wheelbase_m, vehicle.ROLLS)
    values = vehicle.body_values
    assert values.size == body.size
    np.testing.assert_allclose(body.physical(body.theta(values)), values)
    assert values[body.lf_index] == vehicle.cog_from_front_axle_m
    moved = vehicle.with_body_values(values * 1.01)
    np.testing.assert_allclose(moved.body_values, values * 1.01)
    with pytest.raises(ConfigError):
        behind_the_rear_axle = np.where(np.arange(values.size) == body.lf_index, 9.0, values)
        vehicle.with_body_values(behind_the_rear_axle)


@pytest.mark.parametrize("vehicle", [Vehicle(), FullVehicle()], ids=["half", "full"])
def test_a_shifted_sensor_moves_only_its_channel(vehicle):
    moved = shifted_sensor(vehicle, 1, 0.01)
    np.testing.assert_allclose(np.subtract(moved.sensor_x_m, vehicle.sensor_x_m),
                               [0.01 if i == 1 else 0.0 for i in range(len(vehicle.sensor_x_m))], atol=1e-12)
    assert {*vehicle.SENSOR_FIELDS} >= {k for k in vehicle.sensor_shift(1, 0.01)}


def test_a_corner_value_at_zero_has_no_move_and_others_scale():
    half = Vehicle(tyre_damping_front_nspm=0.0)
    assert vehicle_moves(half, "tyre_damping_front_nspm", (0, 1)) == []
    ((name, step, move),) = vehicle_moves(half, "tyre_stiffness_rear_npm", (0, 1))
    assert name == "tyre_stiffness_rear_npm"
    assert move(step).tyre_stiffness_rear_npm == pytest.approx(200_000.0 * (1 + step))
    assert vehicle_moves(FullVehicle(), "anti_roll_stiffness_front_nmprad", (0, 1, 2, 3)) == []
    ((_, step, move),) = vehicle_moves(FullVehicle(), "suspension_stiffness_rear_npm", (0, 1, 2, 3))
    assert move(step).suspension_stiffness_npm == pytest.approx((22_500.0, 22_500.0, 40_000.0 * (1 + step),
                                                                 40_000.0 * (1 + step)))
