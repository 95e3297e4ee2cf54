"""The full car's departures from the estimator's model (the simulator's): a nonlinear
suspension at each corner, the rear sensors late, each sensor's gain."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from fullcar_helpers import ASYMMETRIC
from scipy.integrate import solve_ivp

from rozyn_estimator.body_model import body_rows, sensor_points
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.vehicle_full import FullVehicle
from sim_node.departures import Departures
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation
from sim_node.vehicle_plant import VehiclePlant, static_state

CAR = ASYMMETRIC  # every coupling at work: lateral CoG, unequal corners, bars, sensors off the axles
GAUSSIAN = RoadSpec(amplitudes="gaussian")


def _road(t):
    """Four smooth tracks (FL, FR, RL, RR) and their rates: the rear ones late, left and right apart."""
    t = np.asarray(t, dtype=float)[..., None]
    w = 2 * np.pi * np.array([1.3, 1.7, 1.3, 1.7])
    lag = np.array([0.0, 0.05, 0.1, 0.15])
    w2 = 2 * np.pi * 6.0
    h = 0.01 * np.sin(w * (t - lag)) + 0.003 * np.sin(w2 * (t - lag))
    dh = 0.01 * w * np.cos(w * (t - lag)) + 0.003 * w2 * np.cos(w2 * (t - lag))
    return h, dh


def _corner_ode(v: FullVehicle, ratio: float, progression: float, reference_m: float):
    """The nonlinear full car written out corner by corner, independently of the plant's
    matrices: extension e = body point above the wheel - wheel, rebound e' > 0 at
    c_r = 2c ratio / (1 + ratio), compression at 2c / (1 + ratio), springs
    k e (1 + p (e/e_ref)^2), each bar K/t^2 (e_left - e_right) between its corners."""
    x = np.asarray(v.corner_x_m)
    y = np.asarray(v.corner_y_m) - v.cog_lateral_m
    lever = v.cog_from_front_axle_m - x
    k, c = np.asarray(v.suspension_stiffness_npm), np.asarray(v.suspension_damping_nspm)
    kt, ct, mt = (np.asarray(a) for a in (v.tyre_stiffness_npm, v.tyre_damping_nspm, v.unsprung_mass_kg))
    bars = [(0, 1, v.anti_roll_stiffness_front_nmprad / v.track_front_m**2),
            (2, 3, v.anti_roll_stiffness_rear_nmprad / v.track_rear_m**2)]

    def qdd(t, s):
        xt, xs, phi, theta = s[:4], s[4], s[5], s[6]
        vt, vs, vphi, vtheta = s[7:11], s[11], s[12], s[13]
        e = xs + lever * phi + y * theta - xt
        de = vs + lever * vphi + y * vtheta - vt
        tension = k * e * (1 + progression * (e / reference_m) ** 2)
        tension += np.where(de > 0, 2 * c * ratio / (1 + ratio), 2 * c / (1 + ratio)) * de
        for left, right, stiffness in bars:
            tension[left] += stiffness * (e[left] - e[right])
            tension[right] -= stiffness * (e[left] - e[right])
        h, dh = _road(t)
        wheel = (tension + kt * (h - xt) + ct * (dh - vt)) / mt
        return np.array([*wheel, -tension.sum() / v.sprung_mass_kg,
                         -(lever * tension).sum() / v.pitch_inertia_kgm2,
                         -(y * tension).sum() / v.roll_inertia_kgm2])

    return qdd


@pytest.mark.parametrize(("ratio", "progression"), [(2.0, 0.0), (0.5, 1.0)])
def test_nonlinear_suspension_matches_an_ode_solver(ratio, progression):
    """Asymmetric dampers and progressive springs at all four corners (the bars linear)
    against solve_ivp: the first-order hold of the extra tension, second order in the step."""
    reference_m = 0.02
    qdd = _corner_ode(CAR, ratio, progression, reference_m)
    t_end = 3.0
    t = np.arange(0.0, t_end, 5e-4)
    x0 = static_state(CAR, _road(0.0)[0])
    sol = solve_ivp(lambda tt, s: np.concatenate([s[7:], qdd(tt, s)]), (0, t_end), x0, t_eval=t,
                    rtol=1e-10, atol=1e-12, max_step=5e-4)
    rows = body_rows(CAR, sensor_points(CAR))
    ref = np.array([rows @ qdd(tt, s) for tt, s in zip(t, sol.y.T, strict=True)])
    law = Departures(damper_ratio=ratio, spring_progression=progression,
                     spring_reference_m=reference_m).suspension(CAR)
    errors = []
    for step in (2, 1):  # 1 kHz, 2 kHz
        plant = VehiclePlant(CAR, step * 5e-4, x0=x0, u0=_road(0.0)[0], suspension=law)
        errors.append(np.max(np.abs(plant.run(_road(t[::step])[0]) - ref[::step])) / np.max(np.abs(ref)))
    linear = VehiclePlant(CAR, 1e-3, x0=x0, u0=_road(0.0)[0]).run(_road(t[::2])[0])
    assert np.max(np.abs(linear - ref[::2])) / np.max(np.abs(ref)) > 0.05  # the departure is visible
    assert errors[0] < 3e-4
    assert errors[1] < errors[0] / 3.0


def test_a_nonlinear_run_cut_into_blocks_is_the_whole_run():
    law = Departures(damper_ratio=2.5).suspension(CAR)
    t = np.arange(2000) * 2e-3
    road = _road(t)[0]
    x0 = static_state(CAR, road[0])
    whole = VehiclePlant(CAR, 2e-3, x0=x0, u0=road[0], suspension=law).run(road)
    plant = VehiclePlant(CAR, 2e-3, x0=x0, u0=road[0], suspension=law)
    parts = np.vstack([plant.run(road[a:b]) for a, b in ((0, 1), (1, 7), (7, 300), (300, 2000))])
    assert np.allclose(parts, whole, rtol=0, atol=1e-9 * np.max(np.abs(whole)))


@pytest.mark.parametrize(("delay_s", "refine"), [(0.005, 10), (0.0033, 20)])
def test_the_rear_sensors_late_exactly(delay_s, refine):
    """The rear channels at step k are the on-time outputs at t_k - delay (against a plant
    ``refine`` times finer on the same piecewise-linear road, with a step at every t_k - delay);
    the front channels are untouched."""
    dt, n = 0.002, 2000
    t = np.arange(n) * dt
    road = _road(t)[0]
    x0 = static_state(CAR, road[0])
    delays = (0.0, 0.0, delay_s, delay_s)
    cuts = ((0, 1), (1, 2), (2, 900), (900, n))
    plant = VehiclePlant(CAR, dt, x0=x0, u0=road[0], delays_s=delays)
    late = np.vstack([plant.run(road[a:b]) for a, b in cuts])
    plant = VehiclePlant(CAR, dt, x0=x0, u0=road[0])
    on_time = np.vstack([plant.run(road[a:b]) for a, b in cuts])
    fine_t = np.arange((n - 1) * refine + 1) * (dt / refine)
    fine_road = np.column_stack([np.interp(fine_t, t, road[:, i]) for i in range(4)])
    fine = VehiclePlant(CAR, dt / refine, x0=x0, u0=road[0]).run(fine_road)
    shift = round(delay_s / dt * refine)
    expected = fine[np.arange(n) * refine - shift][shift:]
    assert np.max(np.abs(late[shift:, 2:] - expected[:, 2:])) < 1e-9 * np.max(np.abs(expected))
    assert np.array_equal(late[:, :2], on_time[:, :2])


def test_the_simulation_applies_each_sensors_gain_and_the_rear_delay():
    base = SimConfig(model="full", full_vehicle=CAR, road=GAUSSIAN, seed=3, duration_s=20.0)
    plain = Simulation(base).run(20.0).accel_mps2
    gains = Departures(gain_error_front=0.01, gain_error_rear=-0.02,
                       corner_gain_errors=(0.0, 0.03, 0.0, -0.01))

    def run(departures: Departures) -> np.ndarray:
        return Simulation(dataclasses.replace(base, departures=departures)).run(20.0).accel_mps2

    gained = run(gains)
    assert np.allclose(gained, plain * np.array([1.01, 1.04, 0.98, 0.97]), rtol=1e-13, atol=1e-12)
    late = run(Departures(time_offset_s=0.004))
    assert np.array_equal(late[:, :2], plain[:, :2]) and not np.allclose(late[:, 2:], plain[:, 2:])
    soft = run(Departures(damper_ratio=3.0))
    change = np.std(soft - plain, axis=0) / np.std(plain - 9.80665, axis=0)
    assert np.all(change > 0.02)  # every corner's damper departs


def test_departures_off_are_bit_for_bit_the_run_without_them():
    base = SimConfig(model="full", road=GAUSSIAN, seed=4, duration_s=10.0)
    off = dataclasses.replace(base, departures=Departures(damper_ratio=1.0, corner_gain_errors=(0.0,) * 4))
    assert np.array_equal(Simulation(base).run(10.0).accel_mps2, Simulation(off).run(10.0).accel_mps2)


def test_corner_gains_are_the_full_cars():
    with pytest.raises(ConfigError, match="corner_gain_errors"):
        SimConfig(departures=Departures(corner_gain_errors=(0.01, 0.0, 0.0, 0.0)))
    with pytest.raises(ConfigError, match="corner_gain_errors"):
        Departures(corner_gain_errors=(0.9, 0.0, 0.0, 0.0))
