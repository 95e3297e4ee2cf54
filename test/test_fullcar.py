from __future__ import annotations

import numpy as np
import pytest
from fullcar_helpers import ASYMMETRIC
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from rozyn_estimator.body_model import body_rows, dof, heave_index, second_order_model
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle, centreline_half_car
from sim_node import vehicle_plant
from sim_node.departures import Departures
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation
from sim_node.vehicle_plant import VehiclePlant, static_state

N_DOF = dof(FullVehicle())
HEAVE = heave_index(FullVehicle())
PITCH, ROLL = HEAVE + 1, HEAVE + 2


def test_sign_conventions_follow_rep_103_roll_and_the_half_cars_pitch():
    v = FullVehicle(cog_lateral_m=0.1)
    q = np.zeros(N_DOF)
    q[ROLL] = 0.01  # positive roll: right-handed about +x forward, the left side (y > 0) goes up
    left, right = body_rows(v, np.array([[1.2, 0.5], [1.2, -0.5]])) @ q
    assert left == pytest.approx(0.004) and right == pytest.approx(-0.006)  # lever arms y - y_cog
    q[:] = 0.0
    q[PITCH] = 0.01  # nose up, as the half car: ahead of the CoG up
    front, rear = body_rows(v, np.array([[0.0, 0.0], [2.8, 0.0]])) @ q
    assert front == pytest.approx(0.012) and rear == pytest.approx(-0.016)


def test_matrices_are_symmetric_and_rigid_motions_load_no_spring():
    m = second_order_model(ASYMMETRIC)
    for matrix in (m.stiffness, m.damping):
        assert np.allclose(matrix, matrix.T, rtol=1e-14)
    assert np.allclose(np.diag(m.mass), [21, 19, 34, 31, 1000, 2000, 400])
    # the whole car heaving, pitching or rolling with a plane road under it loads only the tyres' inputs
    v = ASYMMETRIC
    corners = np.column_stack([v.corner_x_m, v.corner_y_m])
    for body in ([1.0, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]):
        q = np.zeros(N_DOF)
        q[HEAVE:] = body
        q[:4] = body_rows(v, corners) @ q  # wheels with the body: no suspension deflection
        assert np.allclose(m.stiffness @ q, m.tyre_stiffness @ q[:4], atol=1e-9)


def test_a_road_raised_evenly_lifts_the_body_by_as_much():
    h = 0.03
    q = static_state(ASYMMETRIC, np.full(4, h))[: N_DOF]
    assert np.allclose(q, [h, h, h, h, h, 0.0, 0.0], atol=1e-12)
    plant = VehiclePlant(ASYMMETRIC, 0.01, x0=static_state(ASYMMETRIC, np.full(4, h)), u0=np.full(4, h))
    assert np.max(np.abs(plant.run(np.full((200, 4), h)))) < 1e-9  # at rest


def test_a_road_higher_on_the_left_rolls_the_body_left_up():
    v = FullVehicle()
    bank = 0.02  # the road plane rises 0.02 m per metre to the left
    q = static_state(v, bank * np.array(v.corner_y_m))[: N_DOF]
    assert q[ROLL] == pytest.approx(bank) and abs(q[HEAVE]) < 1e-12 and abs(q[PITCH]) < 1e-12


def test_free_decay_from_roll_and_pitch_equals_the_matrix_exponential():
    x0 = np.zeros(2 * N_DOF)
    x0[PITCH], x0[ROLL], x0[N_DOF + ROLL] = 0.004, 0.01, 0.05
    dt, n = 0.005, 600
    accel = vehicle_plant.free_decay(ASYMMETRIC, x0, dt, n)
    ss = vehicle_plant.state_space(ASYMMETRIC)
    ref = np.array([ss.c @ expm(ss.a * k * dt) @ x0 for k in range(n)])
    assert np.max(np.abs(accel - ref)) < 1e-10 * np.max(np.abs(ref))
    assert np.max(np.abs(accel[-50:])) < 1e-2 * np.max(np.abs(accel))  # it decays


def test_symmetric_car_rolled_keeps_heave_and_pitch_still():
    x0 = np.zeros(2 * N_DOF)
    x0[ROLL] = 0.01
    v = FullVehicle(anti_roll_stiffness_front_nmprad=10_000.0)
    plant = VehiclePlant(v, 0.005, x0=x0, points_m=np.array([[0.0, 0.0], [2.8, 0.0], [0.0, 0.75]]))
    out = plant.run(np.zeros((400, 4)))
    assert np.max(np.abs(out[:, :2])) < 1e-12 * np.max(np.abs(out[:, 2]))  # centreline: no roll
    assert np.max(np.abs(out[:, 2])) > 0.1


def _road(t):
    """Smooth, different road under each tyre: heights and rates (n, 4)."""
    w = 2 * np.pi * np.array([[1.3], [7.0], [2.1], [0.9]])
    phase = np.array([[0.0], [1.0], [2.0], [3.0]])
    amp = np.array([[0.01], [0.003], [0.008], [0.012]])
    t = np.atleast_1d(t)
    return (amp * np.sin(w * t + phase)).T, (amp * w * np.cos(w * t + phase)).T


def test_road_driven_response_matches_an_ode_solver():
    v = ASYMMETRIC
    m = second_order_model(v)
    minv = np.linalg.inv(m.mass)
    points = np.array([[0.3, 0.7], [2.5, -0.4], [1.2, 0.08]])
    rows = body_rows(v, points)

    def qdd(t, x):
        h, dh = (r[0] for r in _road(t))
        return minv @ (m.tyre_stiffness @ h + m.tyre_damping @ dh - m.stiffness @ x[:7] - m.damping @ x[7:])

    dt, t_end = 1e-3, 3.0
    t = np.arange(0, t_end, dt)
    x0 = static_state(v, _road(0.0)[0][0])
    sol = solve_ivp(lambda tt, x: np.concatenate([x[7:], qdd(tt, x)]), (0, t_end), x0,
                    t_eval=t, rtol=1e-10, atol=1e-12, max_step=dt)
    ref = np.array([rows @ qdd(tt, x) for tt, x in zip(t, sol.y.T, strict=True)])
    accel = VehiclePlant(v, dt, x0=x0, u0=_road(0.0)[0][0], points_m=points).run(_road(t)[0])
    # first-order hold on a smooth road: error shrinks with dt^2
    assert np.max(np.abs(accel - ref)) < 3e-4 * np.max(np.abs(ref))


def test_blocks_concatenate_to_the_whole_run():
    rng = np.random.default_rng(0)
    road = np.cumsum(rng.standard_normal((4000, 4)), axis=0) * 1e-4
    whole = VehiclePlant(ASYMMETRIC, 0.002).run(road)
    plant = VehiclePlant(ASYMMETRIC, 0.002)
    parts = [plant.run(road[a:b]) for a, b in [(0, 1), (1, 1), (1, 777), (777, 4000)]]
    assert np.allclose(np.vstack(parts), whole, rtol=1e-12, atol=1e-15)


def test_symmetric_full_car_is_its_centreline_half_car():
    """Heave and pitch of a symmetric full car on any two tracks are the centreline half car's
    on the tracks' mean: at the centreline points, to 1e-9 of the signal (rounding only)."""
    full = FullVehicle(sprung_mass_kg=1300.0, pitch_inertia_kgm2=2500.0, cog_from_front_axle_m=1.3,
                       anti_roll_stiffness_front_nmprad=20_000.0, track_rear_m=1.6,
                       sensor_x_m=(0.1, 0.1, 2.7, 2.7), sensor_y_m=(0.5, -0.5, 0.6, -0.6))
    half = centreline_half_car(full)
    rng = np.random.default_rng(1)
    road = np.cumsum(rng.standard_normal((3000, 4)), axis=0) * 1e-4  # FL, FR, RL, RR, all different
    dt = 0.002
    centre = VehiclePlant(full, dt, points_m=np.array([[0.1, 0.0], [2.7, 0.0]])).run(road)
    pairs = VehiclePlant(full, dt).run(road)  # the four sensors: left/right means are the centreline
    expected = vehicle_plant.VehiclePlant(half, dt).run(0.5 * (road[:, ::2] + road[:, 1::2]))
    scale = np.max(np.abs(expected))
    assert np.max(np.abs(centre - expected)) < 1e-9 * scale
    assert np.max(np.abs(0.5 * (pairs[:, ::2] + pairs[:, 1::2]) - expected)) < 1e-9 * scale
    assert np.allclose(vehicle_plant.natural_modes(full)[0][[0, 1]], vehicle_plant.natural_modes(half)[0][:2])


def _roll_mode_hz(v: FullVehicle) -> float:
    """Frequency of the body's roll mode: the slowest whose shape moves no heave and no pitch (a
    symmetric car's; the antisymmetric wheel hop is the other such mode)."""
    lam, vec = np.linalg.eig(vehicle_plant.state_space(v).a)
    body = np.abs(vec[HEAVE : ROLL + 1])
    roll_like = (body[2] > 1e6 * np.maximum(body[0], body[1])) & (lam.imag > 0)
    return float(np.min(np.abs(lam[roll_like])) / (2 * np.pi))


@pytest.mark.parametrize("bars_nmprad", [(0.0, 0.0), (12_000.0, 3000.0)])
def test_roll_mode_frequency_is_sqrt_of_roll_stiffness_over_inertia(bars_nmprad):
    """Stiff tyres decouple the body from the wheels: roll at sqrt(K_roll / I_xx) to 0.5 %, with
    K_roll = sum k_s y^2 + the bars (the wheels' inertia and the tyres' compliance: second order)."""
    front, rear = bars_nmprad
    v = FullVehicle(tyre_stiffness_npm=(1e8,) * 4, suspension_damping_nspm=(1.0,) * 4,
                    anti_roll_stiffness_front_nmprad=front, anti_roll_stiffness_rear_nmprad=rear,
                    track_rear_m=1.4, roll_inertia_kgm2=450.0)
    springs = zip(v.suspension_stiffness_npm, v.corner_y_m, strict=True)
    k_roll = sum(k * y**2 for k, y in springs) + front + rear
    expected_hz = np.sqrt(k_roll / v.roll_inertia_kgm2) / (2 * np.pi)
    assert _roll_mode_hz(v) == pytest.approx(expected_hz, rel=5e-3)


def test_bad_arguments():
    with pytest.raises(ValueError, match="dt_s"):
        VehiclePlant(FullVehicle(), 0.0)
    with pytest.raises(ValueError, match=r"\(n, 4\)"):
        VehiclePlant(FullVehicle(), 0.01).run(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="points_m"):
        VehiclePlant(FullVehicle(), 0.01, points_m=np.zeros((2, 3)))


def test_simulation_runs_the_full_car_in_blocks():
    cfg = SimConfig(model="full", seed=3, noise_std_mps2=0.05, full_vehicle=ASYMMETRIC)
    whole = Simulation(cfg).run(4.0)
    sim = Simulation(cfg)
    parts = [sim.next_block(k) for k in (1, 150, 0, 249)]
    assert whole.channels == ("front_left", "front_right", "rear_left", "rear_right")
    assert whole.accel_mps2.shape == (400, 4)
    assert np.allclose(np.vstack([p.accel_mps2 for p in parts]), whole.accel_mps2, rtol=1e-10, atol=1e-12)
    assert whole.accel_mps2.mean() == pytest.approx(9.80665, abs=0.05)  # REP 145: +g
    assert cfg.plant_vehicle is ASYMMETRIC


def test_simulation_identical_tracks_drive_no_roll():
    """Coherence 1: the same road under left and right wheels; a symmetric car does not roll, and
    each side reads the half car's accelerations on that road (the half car's own run)."""
    full = FullVehicle()
    cfg = SimConfig(model="full", seed=5, track_coherence="identical", full_vehicle=full)
    accel = Simulation(cfg).run(5.0).accel_mps2
    half = Simulation(SimConfig(seed=5, vehicle=centreline_half_car(full))).run(5.0).accel_mps2
    scale = np.max(np.abs(half - 9.80665))
    assert np.max(np.abs(accel[:, [0, 2]] - half)) < 1e-9 * scale
    assert np.max(np.abs(accel[:, [1, 3]] - half)) < 1e-9 * scale


@pytest.mark.parametrize(
    ("changes", "field"),
    [({"full_vehicle": FullVehicle()}, "full_vehicle"),
     ({"departures": Departures(corner_gain_errors=(0.01, 0.0, 0.0, 0.0))}, "corner_gain_errors"),
     ({"model": "full", "bias_mps2": (0.1, 0.0)}, "bias_mps2"),
     ({"model": "full", "initial_state": (0.0,) * 8}, "initial_state"),
     ({"model": "full", "vehicle": Vehicle(sprung_mass_kg=900.0)}, "vehicle"),
     ({"model": "quarter"}, "model"), ({"track_coherence": "none"}, "track_coherence")],
)
def test_simulation_refuses_what_the_full_car_does_not_simulate(changes, field):
    with pytest.raises(ConfigError, match=field):
        SimConfig(**changes)


def test_full_car_free_decay_and_lowpass_on_a_flat_road():
    cfg = SimConfig(model="full", road=RoadSpec(kind="flat"), departures=Departures(lowpass_hz=30.0),
                    include_gravity=False)
    a = Simulation(cfg).run(10.0).accel_mps2
    assert a[:50].max() > 1.0 and a[-50:].max() < 1e-3
    assert np.allclose(a[:, 0], a[:, 1]) and np.allclose(a[:, 2], a[:, 3])  # no roll in the start
