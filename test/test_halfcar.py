from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from rozyn_estimator.body_model import body_rows, second_order_model, sensor_rows, suspension_rows
from rozyn_estimator.vehicle import Vehicle
from sim_node.departures import Departures
from sim_node.vehicle_plant import VehiclePlant, free_decay, natural_modes, state_space, static_state


def test_matrices_follow_eqs_3_4_to_3_7_with_typos_fixed(vehicle):
    m = second_order_model(vehicle)
    lf, lr = 1.2, 1.6
    assert np.allclose(m.stiffness, m.stiffness.T) and np.allclose(m.damping, m.damping.T)
    # eq 3-6 prints l_f * c_s_r in row 2; the rear damper acts at l_r
    assert m.damping[1, 3] == pytest.approx(lr * 3500.0)
    assert m.stiffness[3, 3] == pytest.approx(lf**2 * 45000 + lr**2 * 80000)
    assert m.stiffness[0, 0] == pytest.approx(245000.0)
    assert np.allclose(np.diag(m.mass), [40, 65, 1000, 2000])
    # a rigid heave of body and wheels with the road does not load the springs
    q = np.array([1.0, 1.0, 1.0, 0.0])
    assert np.allclose(m.stiffness @ q, m.tyre_stiffness @ [1.0, 1.0])


def test_sensor_rows_use_lr_behind_the_cog(vehicle):
    rows = sensor_rows(vehicle)
    assert np.allclose(rows, [[0, 0, 1, 1.2], [0, 0, 1, -1.6]])  # eqs 3-8, 3-9 corrected


def test_natural_modes_of_table_5_1(vehicle):
    freq, zeta = natural_modes(vehicle)
    assert freq[:2] == pytest.approx([1.288, 1.857], abs=2e-3)
    assert zeta[:2] == pytest.approx([0.203, 0.174], abs=2e-3)
    assert 9 < freq[2] < freq[3] < 13  # wheel hop


def test_free_decay_equals_matrix_exponential(vehicle):
    x0 = np.array([-0.015, -0.015, -0.03, 0.002, 0, 0, 0.1, 0])
    dt, n = 0.005, 600
    accel = free_decay(vehicle, x0, dt, n)
    ss = state_space(vehicle)
    ref = np.array([sensor_rows(vehicle) @ (ss.a @ expm(ss.a * k * dt) @ x0)[4:] for k in range(n)])
    assert np.max(np.abs(accel - ref)) < 1e-10 * np.max(np.abs(ref))


def _road(t):
    w1, w2 = 2 * np.pi * 1.3, 2 * np.pi * 7.0
    h = np.stack([0.01 * np.sin(w1 * t) + 0.003 * np.sin(w2 * t), 0.01 * np.sin(w1 * (t - 0.1))], -1)
    dh = np.stack([0.01 * w1 * np.cos(w1 * t) + 0.003 * w2 * np.cos(w2 * t),
                   0.01 * w1 * np.cos(w1 * (t - 0.1))], -1)
    return h, dh


def test_road_driven_response_matches_an_ode_solver(vehicle):
    m = second_order_model(vehicle)
    minv = np.linalg.inv(m.mass)

    def qdd(t, x):
        h, dh = _road(t)
        return minv @ (m.tyre_stiffness @ h + m.tyre_damping @ dh - m.stiffness @ x[:4] - m.damping @ x[4:])

    dt, t_end = 1e-3, 4.0
    t = np.arange(0, t_end, dt)
    x0 = static_state(vehicle, _road(0.0)[0])
    sol = solve_ivp(lambda tt, x: np.concatenate([x[4:], qdd(tt, x)]), (0, t_end), x0,
                    t_eval=t, rtol=1e-10, atol=1e-12, max_step=dt)
    ref = np.array([sensor_rows(vehicle) @ qdd(tt, x) for tt, x in zip(t, sol.y.T, strict=True)])
    plant = VehiclePlant(vehicle, dt, x0=x0, u0=_road(0.0)[0])
    accel = plant.run(_road(t)[0])
    # first-order hold on a smooth road: error shrinks with dt^2; 1e-4 relative at 1 kHz
    assert np.max(np.abs(accel - ref)) < 3e-4 * np.max(np.abs(ref))


def test_blocks_concatenate_to_the_whole_run(vehicle):
    rng = np.random.default_rng(0)
    road = np.cumsum(rng.standard_normal((5000, 2)), axis=0) * 1e-4
    whole = VehiclePlant(vehicle, 0.002).run(road)
    plant = VehiclePlant(vehicle, 0.002)
    parts = [plant.run(road[a:b]) for a, b in [(0, 1), (1, 1), (1, 777), (777, 5000)]]
    # equal up to rounding (BLAS kernels differ with block length)
    assert np.allclose(np.vstack(parts), whole, rtol=1e-12, atol=1e-15)


def test_static_state_is_at_rest(vehicle):
    u = np.array([0.02, -0.01])
    plant = VehiclePlant(vehicle, 0.01, x0=static_state(vehicle, u), u0=u)
    assert np.max(np.abs(plant.run(np.tile(u, (200, 1))))) < 1e-9


def test_bad_arguments(vehicle):
    with pytest.raises(ValueError, match="dt_s"):
        VehiclePlant(vehicle, 0.0)
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        VehiclePlant(vehicle, 0.01).run(np.zeros(10))
    with pytest.raises(ValueError, match="centreline"):  # a half car does not roll
        VehiclePlant(vehicle, 0.01, points_m=np.array([[0.5, 0.3]]))


def test_points_on_the_body_read_its_heave_and_pitch(vehicle):
    q = np.zeros(4)
    q[2], q[3] = 0.01, 0.002  # heave at the CoG, pitch nose up
    points = np.array([[0.0, 0.0], [1.2, 0.0], [2.8, 0.0]])
    plant = VehiclePlant(vehicle, 0.01, points_m=points)
    assert plant.n_road == 2
    assert body_rows(vehicle, points) @ q == pytest.approx([0.01 + 1.2 * 0.002, 0.01, 0.01 - 1.6 * 0.002])


def test_other_vehicle_modes_move():
    heavy = Vehicle(sprung_mass_kg=1800.0, pitch_inertia_kgm2=3600.0, wheelbase_m=3.2,
                    cog_from_front_axle_m=1.5)
    assert natural_modes(heavy)[0][0] < natural_modes(Vehicle())[0][0]


def _corner_ode(v, road, ratio, progression, reference_m):
    """The nonlinear half car written out corner by corner, independently of the plant's
    matrices: extension e = body point above the axle - wheel, rebound v = e' > 0 at
    c_r = 2c ratio / (1 + ratio), compression at c_c = 2c / (1 + ratio), spring
    k e (1 + p (e/e_ref)^2); tension pulls body and wheel together."""
    lf, lr = v.cog_from_front_axle_m, v.cog_from_rear_axle_m
    k = np.array([v.suspension_stiffness_front_npm, v.suspension_stiffness_rear_npm])
    c = np.array([v.suspension_damping_front_nspm, v.suspension_damping_rear_nspm])
    kt = np.array([v.tyre_stiffness_front_npm, v.tyre_stiffness_rear_npm])
    ct = np.array([v.tyre_damping_front_nspm, v.tyre_damping_rear_nspm])
    mt = np.array([v.unsprung_mass_front_kg, v.unsprung_mass_rear_kg])

    def qdd(t, x):
        xt, xs, phi = x[:2], x[2], x[3]
        vt, vs, vphi = x[4:6], x[6], x[7]
        e = np.array([xs + lf * phi, xs - lr * phi]) - xt
        de = np.array([vs + lf * vphi, vs - lr * vphi]) - vt
        damper = np.where(de > 0, 2 * c * ratio / (1 + ratio), 2 * c / (1 + ratio)) * de
        tension = k * e * (1 + progression * (e / reference_m) ** 2) + damper
        h, dh = road(t)
        wheel = (tension + kt * (h - xt) + ct * (dh - vt)) / mt
        body = -tension.sum() / v.sprung_mass_kg
        pitch = (-lf * tension[0] + lr * tension[1]) / v.pitch_inertia_kgm2
        return np.array([*wheel, body, pitch])

    return qdd


@pytest.mark.parametrize(("ratio", "progression"), [(2.0, 0.0), (0.5, 1.0)])
def test_nonlinear_suspension_matches_an_ode_solver(vehicle, ratio, progression):
    """Asymmetric dampers and progressive springs against solve_ivp on the nonlinear ODE.

    The plant holds the extra tension piecewise linear between steps: its error is second
    order in the step, 1-2e-4 of the largest acceleration at 1 kHz, 3-5e-5 at 2 kHz, where
    the departures change the accelerations by 9 % (dampers 2:1) to 50 % (springs)."""
    reference_m = 0.02
    qdd = _corner_ode(vehicle, _road, ratio, progression, reference_m)
    t_end = 3.0
    t = np.arange(0.0, t_end, 5e-4)
    x0 = static_state(vehicle, _road(0.0)[0])
    sol = solve_ivp(lambda tt, x: np.concatenate([x[4:], qdd(tt, x)]), (0, t_end), x0, t_eval=t,
                    rtol=1e-10, atol=1e-12, max_step=5e-4)
    ref = np.array([sensor_rows(vehicle) @ qdd(tt, x) for tt, x in zip(t, sol.y.T, strict=True)])
    law = Departures(damper_ratio=ratio, spring_progression=progression,
                     spring_reference_m=reference_m).suspension(vehicle)
    errors = []
    for step in (2, 1):  # 1 kHz, 2 kHz
        plant = VehiclePlant(vehicle, step * 5e-4, x0=x0, u0=_road(0.0)[0], suspension=law)
        errors.append(np.max(np.abs(plant.run(_road(t[::step])[0]) - ref[::step])) / np.max(np.abs(ref)))
    linear = VehiclePlant(vehicle, 1e-3, x0=x0, u0=_road(0.0)[0]).run(_road(t[::2])[0])
    assert np.max(np.abs(linear - ref[::2])) / np.max(np.abs(ref)) > 0.05  # the departure is visible
    assert errors[0] < 3e-4
    assert errors[1] < errors[0] / 3.0  # second order in the step


def test_suspension_rows_give_eq_3_5s_suspension_part(vehicle):
    g = suspension_rows(vehicle)
    k = np.diag([vehicle.suspension_stiffness_front_npm, vehicle.suspension_stiffness_rear_npm])
    tyres = np.diag([vehicle.tyre_stiffness_front_npm, vehicle.tyre_stiffness_rear_npm, 0.0, 0.0])
    assert np.allclose(g.T @ k @ g + tyres, second_order_model(vehicle).stiffness)
    # extension: body up or wheels down extend, nose up extends the front and compresses the rear
    assert np.allclose(g @ [0, 0, 1, 0], [1, 1]) and np.allclose(g @ [1, 1, 0, 0], [-1, -1])
    assert np.allclose(g @ [0, 0, 0, 1], [1.2, -1.6])
