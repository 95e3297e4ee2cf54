"""One spectral model for every car: the half car through the full car's model (two corners on
the centreline, one track, the body's heave and pitch) is the half car's own model, its
spectral matrix and every derivative, at a constant and a varying speed, with the weight
through the geometry, for two accelerometers and for one IMU, and with the sensors' and the
corners' calibrations."""

import numpy as np
import pytest

from rozyn_estimator.method.body_parameters import BodyParameters
from rozyn_estimator.method.full.fit import corner_value_count
from rozyn_estimator.method.full.spectrum import FullCarSpectrum
from rozyn_estimator.method.likelihood.model import HalfCarSpectrum
from rozyn_estimator.sensors import sensors_from_mapping
from rozyn_estimator.vehicle import Vehicle

FS_HZ = 100.0
FREQ_HZ = np.linspace(0.5, 20.0, 240)
VARYING_MPS = np.r_[np.full(3000, 8.0), np.linspace(8.0, 22.0, 6000), np.full(3000, 22.0)]
GEOMETRY = dict(cog_height_m=0.55, wheel_centre_height_m=0.3)
IMU = {"names": ["imu"],
       "imu": {"topic": "/imu/data", "x_m": 1.5, "y_m": 0.0, "channels": ["accel_z", "gyro_y"]}}
PARAMS = np.array([950.0, 1400.0, 1.3])  # m, I_yy, l_f
# the half car's θ names for the one model's
SAME = {"ln_pitch_inertia": "ln_inertia", "ln_noise_0": "ln_noise_front", "ln_noise_1": "ln_noise_rear",
        "ln_gain_1": "ln_rear_gain", "delay_ms": "time_offset_ms"}


def _models(v: Vehicle, speed, **half) -> tuple[HalfCarSpectrum, np.ndarray, FullCarSpectrum, np.ndarray]:
    h = HalfCarSpectrum(v, FREQ_HZ, FS_HZ, speed, aliases=1, estimate_waviness=True, road_shape_terms=2,
                        **half)
    one = FullCarSpectrum(v, (0, 1), FREQ_HZ, FS_HZ, speed, aliases=1, road_shape_terms=2)
    th_h = h.theta(PARAMS, 3e-6, np.array([1e-4, 2e-4]), waviness=2.3)
    th_h[h.shape_slice] = [0.2, -0.1]
    th_one = one.theta(PARAMS, 3e-6, np.array([1e-4, 2e-4]))
    th_one[one.waviness_index] = 2.3
    th_one[one.shape_slice] = [0.2, -0.1]
    return h, th_h, one, th_one


def _close(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12 * float(np.max(np.abs(a))))


@pytest.mark.parametrize("speed", [27.0, VARYING_MPS], ids=["constant", "varying"])
@pytest.mark.parametrize("sensors", [None, IMU], ids=["two accelerometers", "one IMU"])
def test_the_half_car_is_the_one_models_two_corner_case(speed, sensors):
    v = Vehicle(sensor_front_offset_m=0.2, sensor_rear_offset_m=-0.3, **GEOMETRY)
    if sensors is not None:
        v = v.with_sensors(sensors_from_mapping(sensors))
    h, th_h, one, th_one = _models(v, speed)
    assert one.names == ["ln_mass", "ln_pitch_inertia", "logit_cog", "ln_road", "waviness", "road_shape_2",
                         "road_shape_3", "ln_noise_0", "ln_noise_1"]
    np.testing.assert_allclose(one.physical(th_one), h.physical(th_h), rtol=1e-12)
    S_h, dS_h = h.spectrum(th_h)
    S_one, dS_one = one.spectrum(th_one)
    _close(S_h, S_one)
    for name in one.names:
        _close(dS_h[h.index[SAME.get(name, name)]], dS_one[one.index[name]])


def test_the_rear_sensors_gain_and_delay_calibrate_alike():
    """The half car's rear gain and delay are the one model's second gain and its delay."""
    v = Vehicle(**GEOMETRY)
    h, th_h, one, th_one = _models(v, 27.0, calibrate_gain=True, calibrate_time_offset=True)
    one = one.calibrating(("gain", "delay"))
    th_one = np.r_[th_one, np.zeros(len(one.names) - th_one.size)]
    th_h[h.index["ln_rear_gain"]] = th_one[one.index["ln_gain_1"]] = 0.05
    th_h[h.index["time_offset_ms"]] = th_one[one.index["delay_ms"]] = 3.0
    S_h, dS_h = h.spectrum(th_h)
    S_one, dS_one = one.spectrum(th_one)
    _close(S_h, S_one)
    for name in ("ln_gain_1", "delay_ms", "ln_mass"):
        _close(dS_h[h.index[SAME.get(name, name)]], dS_one[one.index[name]])


def test_the_corners_derivatives_are_the_half_cars_corner_terms():
    """The one model's derivative along a corner value is the half car's along its log scale
    (the value times it): suspension, tyre and wheel of each axle."""
    terms = ("stiffness", "damping", "tyre_stiffness", "tyre_damping", "unsprung_mass")
    v = Vehicle(**GEOMETRY)
    h, th_h, one, th_one = _models(v, 27.0, corner_terms=terms)
    _, dS_h = h.spectrum(th_h)
    base = np.array([v.suspension_stiffness_front_npm, v.suspension_stiffness_rear_npm,
                     v.suspension_damping_front_nspm, v.suspension_damping_rear_nspm,
                     v.tyre_stiffness_front_npm, v.tyre_stiffness_rear_npm,
                     v.tyre_damping_front_nspm, v.tyre_damping_rear_nspm,
                     v.unsprung_mass_front_kg, v.unsprung_mass_rear_kg])
    assert corner_value_count(v) == base.size
    got = one.to_targets(one.corner_derivatives(th_one, np.diag(base)))
    for i, term in enumerate(terms):
        for j, corner in enumerate(("front", "rear")):
            _close(dS_h[h.index[f"ln_{term}_{corner}"]], got[2 * i + j])


def test_the_body_parameters_map_both_ways():
    """θ's body block and the physical parameters are each other's inverse, for both bodies,
    and the Jacobian is their slope."""
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
