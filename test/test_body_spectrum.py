"""One spectral model for every car: the half car is its two-corner case on the centreline (one
track, the body's heave and pitch). Checked against the simulator's plant (its state space, an
independent implementation of the equations of motion) and against finite differences of
itself, at a constant and a varying speed, with the weight through the geometry, for two
accelerometers and for one IMU, and with the sensors' and the corners' calibrations."""

import numpy as np
import pytest
from spectrum_helpers import assert_slopes, model_response, plant_response

from rozyn_estimator.method.body_parameters import BodyParameters
from rozyn_estimator.method.vehicle_fit.corner_matrices import corner_value_count
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.uncertainty.moves import values_of
from rozyn_estimator.sensors import sensors_from_mapping
from rozyn_estimator.vehicle import Vehicle

FS_HZ = 100.0
FREQ_HZ = np.linspace(0.5, 20.0, 120)
VARYING_MPS = np.r_[np.full(3000, 8.0), np.linspace(8.0, 22.0, 6000), np.full(3000, 22.0)]
GEOMETRY = dict(cog_height_m=0.55, wheel_centre_height_m=0.3)
IMU = {"names": ["imu"],
       "imu": {"topic": "/imu/data", "x_m": 1.5, "y_m": 0.0, "channels": ["accel_z", "gyro_y"]}}
PARAMS = np.array([950.0, 1400.0, 1.3])  # m, I_yy, l_f


def _vehicle(sensors: dict | None = None) -> Vehicle:
    v = Vehicle(sensor_front_offset_m=0.2, sensor_rear_offset_m=-0.3, **GEOMETRY)
    return v if sensors is None else v.with_sensors(sensors_from_mapping(sensors))


def _theta(model: VehicleSpectrum, params: np.ndarray = PARAMS) -> np.ndarray:
    theta = model.theta(params, 3e-6, np.array([1e-4, 2e-4]))
    theta[model.waviness_index] = 2.3
    theta[model.shape_slice] = [0.2, -0.1]
    return np.r_[theta, np.full(model.n_params - theta.size, 0.01)]  # calibrated values, if any


@pytest.mark.parametrize("sensors", [None, IMU], ids=["two accelerometers", "one IMU"])
def test_the_half_car_is_the_simulators_transfer_function(sensors):
    """G = iω P D⁻¹ Bᵀ T per unit road velocity at each wheel equals the plant's state space
    (the road under each wheel in, the channels out) divided by iω."""
    v = _vehicle(sensors)
    model = VehicleSpectrum(v, (0, 1), FREQ_HZ, FS_HZ, 20.0, aliases=0)
    truth = np.array([v.sprung_mass_kg, v.pitch_inertia_kgm2, v.cog_from_front_axle_m])
    theta = model.theta(truth, 1.0, np.ones(2))
    plant = plant_response(v, FREQ_HZ)
    assert model.names[:3] == ["ln_mass", "ln_pitch_inertia", "logit_cog"]
    assert "ln_coherence_scale" not in model.names  # one track
    assert np.max(np.abs(model_response(model, theta) - plant)) < 1e-9 * np.max(np.abs(plant))


@pytest.mark.parametrize("speed", [27.0, VARYING_MPS], ids=["constant", "varying"])
@pytest.mark.parametrize(("sensors", "calibrate"), [(None, ("gain", "x", "delay")), (IMU, ("gain", "delay"))],
                         ids=["two accelerometers", "one IMU"])
def test_every_derivative_of_the_half_car_is_its_slope(speed, sensors, calibrate):
    model = VehicleSpectrum(_vehicle(sensors), (0, 1), FREQ_HZ, FS_HZ, speed, aliases=1, road_shape_terms=2,
                            calibrate=calibrate)
    assert_slopes(model, _theta(model), rtol=1e-5, atol=1e-30)


def test_the_corners_derivatives_are_the_half_cars_slopes():
    """Along each corner value (spring, damper, tyre, wheel of each axle) the model's analytic
    derivative is its change with the vehicle moved."""
    v = _vehicle()
    model = VehicleSpectrum(v, (0, 1), FREQ_HZ, FS_HZ, 27.0, aliases=1, road_shape_terms=2)
    theta = _theta(model)
    base = values_of(v)
    assert corner_value_count(v) == base.size == 10
    got = model.to_targets(model.corner_derivatives(theta, np.diag(base)))
    fields = ("suspension_stiffness", "suspension_damping", "tyre_stiffness", "tyre_damping", "unsprung_mass")
    units = ("npm", "nspm", "npm", "nspm", "kg")
    for i, (field, unit) in enumerate(zip(fields, units, strict=True)):
        for j, corner in enumerate(("front", "rear")):
            name = f"{field}_{corner}_{unit}"
            value = getattr(v, name)
            moved = []
            for h in (1e-6, -1e-6):
                with model.assuming(v.replace(**{name: value * (1 + h)})):
                    moved.append(model.spectrum(theta, False)[0])
            slope = (moved[0] - moved[1]) / 2e-6
            assert np.max(np.abs(slope - got[2 * i + j])) < 1e-5 * np.max(np.abs(slope)), name


def test_the_body_parameters_map_both_ways():
    """θ's body block and the physical parameters are each other's inverse, for both bodies,
    and the Jacobian and the mass matrix's derivatives are their slopes."""
    for rolls, params in ((False, PARAMS), (True, np.array([950.0, 420.0, 1400.0, 1.3, 0.03]))):
        body = BodyParameters(2.8, rolls, 0.25, 110.0)
        theta = body.theta(params)
        np.testing.assert_allclose(body.physical(theta), params, rtol=1e-12)
        step = 1e-6
        slope = np.column_stack([(body.physical(theta + step * e) - body.physical(theta - step * e))
                                 / (2 * step) for e in np.eye(theta.size)])
        np.testing.assert_allclose(body.jacobian(theta), slope, rtol=1e-6, atol=1e-9)
        M, dM = body.mass_matrix(theta)
        assert M.shape == (body.coordinates,) * 2 and dM.shape == (body.size, *M.shape)
        num = np.array([(body.mass_matrix(theta + step * e)[0] - body.mass_matrix(theta - step * e)[0])
                        / (2 * step) for e in np.eye(theta.size)])
        np.testing.assert_allclose(dM, num, rtol=1e-6, atol=1e-6)
