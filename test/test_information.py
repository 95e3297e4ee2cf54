"""What each channel contributes: the share of each parameter's information lost without it."""

from __future__ import annotations

import numpy as np

from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.method.information import describe, information_lost
from rozyn_estimator.method.pipeline import estimate
from rozyn_estimator.online.records import OK, Update, layout_of, update_values
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle
from sim_node.simulation import SimConfig, Simulation


def test_a_parameter_only_one_channel_sees_is_lost_without_it():
    K, f = 300, np.linspace(1.0, 3.0, 300)
    S = np.zeros((K, 2, 2), complex)
    S[:, 0, 0], S[:, 1, 1] = 1.0, 2.0
    dS = np.zeros((3, K, 2, 2), complex)
    dS[0, :, 0, 0], dS[1, :, 1, 1], dS[2, :, 0, 0] = 1.0, 2.0, f  # p0, p2: channel 0; p1: channel 1
    lost = information_lost(S, dS, None, np.eye(3))
    np.testing.assert_allclose(lost, [[1.0, 0.0, 1.0], [0.0, 1.0, 0.0]], atol=1e-9)


def test_the_shares_are_the_sub_models_inverse_information():
    """Against the Fisher information summed term by term, with correlated channels."""
    rng = np.random.default_rng(1)
    K, k, p = 40, 3, 4
    A = rng.standard_normal((K, k, k)) + 1j * rng.standard_normal((K, k, k))
    S = A @ A.conj().transpose(0, 2, 1) + 3 * np.eye(k)
    B = rng.standard_normal((p, K, k, k)) + 1j * rng.standard_normal((p, K, k, k))
    dS = B + B.conj().swapaxes(-1, -2)
    w = rng.uniform(1, 3, K)
    jac = rng.standard_normal((2, p))

    def variances(keep):
        F = np.zeros((p, p))
        for f in range(K):
            inv = np.linalg.inv(S[f][np.ix_(keep, keep)])
            parts = [inv @ dS[i, f][np.ix_(keep, keep)] for i in range(p)]
            F += w[f] * np.array([[np.trace(a @ b).real for b in parts] for a in parts])
        return np.diag(jac @ np.linalg.inv(F) @ jac.T)

    full = variances([0, 1, 2])
    want = np.array([1 - full / variances([j for j in range(k) if j != c]) for c in range(k)])
    np.testing.assert_allclose(information_lost(S, dS, w, jac), want, rtol=1e-6, atol=1e-9)


def test_four_corners_share_what_one_imu_needs_all_of():
    """Four corner accelerometers tell the body with any three (each carries a part); one IMU's
    accelerometer and pitch gyro carry all of m and I_yy; the diagnostics name each share."""
    exact = FullTolerances(**{key: 0.0 for key in FullTolerances().to_dict()})
    v = FullVehicle(tolerances=exact)
    y = Simulation(SimConfig(model="full", full_vehicle=v, seed=2, duration_s=120)).run(120).accel_mps2
    y = y + 0.1 * y.std(axis=0) * np.random.default_rng(2).standard_normal(y.shape)
    e = estimate(y, 100.0, v, PipelineConfig(), speed_mps=100 / 3.6)
    assert e.ok and e.refinement is not None, e.reason
    lost = np.array(e.refinement.information_lost)
    assert lost.shape == (4, 5) and np.all((lost >= 0) & (lost <= 1))
    assert np.all(lost[:, 0] < 0.8)  # m: the other three corners carry most of it
    values = update_values(Update(1, OK, "ok", e), layout_of(v))
    assert values["information_lost_without_front_left"] == describe(lost[0], FULL_PARAM_NAMES)
    assert values["information_lost_without_front_left"].startswith("m ")
