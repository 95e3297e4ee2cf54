"""One likelihood refinement for every car: the half car through the full car's refinement (the
one spectral model, its fit, calibration and budget) estimates what the half car's own does, to
a small share of the std, exact and with the default tolerances."""

import numpy as np
import pytest

from rozyn_estimator.method.full.refine import refine_full
from rozyn_estimator.method.likelihood.fit import refine
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle
from sim_node.simulation import SimConfig, Simulation

SPEED_MPS = 100 / 3.6
START = np.array([1050.0, 2100.0, 1.26])  # 5 % off the truth, as Rozyn's stage may be


def _window(seed: int) -> np.ndarray:
    y = Simulation(SimConfig(vehicle=Vehicle(), seed=seed, duration_s=120)).run(120).accel_mps2
    return y + 0.1 * y.std(axis=0) * np.random.default_rng(seed + 1000).standard_normal(y.shape)


def _total(covariance: np.ndarray, contributions: dict[str, np.ndarray]) -> np.ndarray:
    return covariance + sum((np.outer(c, c) for c in contributions.values()), np.zeros_like(covariance))


@pytest.mark.parametrize("tolerances", [Tolerances.none(), Tolerances()], ids=["exact", "default tolerances"])
def test_the_half_car_through_the_one_refinement_is_its_own(tolerances):
    v = Vehicle(tolerances=tolerances)
    y = _window(5)
    own = refine(y, 100.0, v, START, SPEED_MPS)
    one = refine_full(y, 100.0, v, (0, 1), START, SPEED_MPS)
    assert own.ok and one.ok, (own.reason, one.reason)
    assert one.params.shape == (3,) and one.names[:3] == ("ln_mass", "ln_pitch_inertia", "logit_cog")
    std = np.sqrt(np.diag(_total(own.covariance, own.contributions)))
    assert np.all(np.abs(one.params - own.params) < 0.1 * std), (one.params, own.params, std)
    one_std = np.sqrt(np.diag(_total(one.covariance, one.contributions)))
    np.testing.assert_allclose(one_std, std, rtol=0.1)
    if tolerances.any:  # the same values calibrated: each corner's and sensor's
        assert one.calibration is not None and len(one.calibration.corner_keys) == 10
        assert set(one.calibration.groups) == {"gain", "x", "delay"}
