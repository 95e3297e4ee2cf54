"""When a fit has converged (:func:`converged`: the whole Newton decrement, or the body's part
of it) and when S is too nearly singular for the grid (:func:`nearly_singular`): the work an
urban window's update spends."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rozyn_estimator.method import PipelineConfig, estimate
from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.guards import NEARLY_SINGULAR, nearly_singular
from rozyn_estimator.method.vehicle_fit import refine as refine_module
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.whittle import converged
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle
from sim_node.road import RoadSpec
from sim_node.sensors import MEMS_NOISE_MPS2
from sim_node.simulation import SimConfig, Simulation


class _Quadratic:
    """ℓ = ½ (θ - θ*)ᵀ H (θ - θ*): its gradient and Hessian, as the objective's."""

    def __init__(self, hessian: np.ndarray, optimum: np.ndarray) -> None:
        self.hessian, self.optimum = hessian, optimum

    def jac(self, theta: np.ndarray) -> np.ndarray:
        return self.hessian @ (theta - self.optimum)

    def hess(self, theta: np.ndarray) -> np.ndarray:
        return self.hessian


# two body parameters and a nuisance correlated with the first
_H = np.array([[4.0, 0.0, 1.0], [0.0, 2.0, 0.0], [1.0, 0.0, 1.0]])


@pytest.mark.parametrize("theta, body, expected", [
    ((0.0, 0.0, 0.0), 0, True),  # at the optimum
    ((0.0, 0.0, 0.2), 0, False),  # the nuisance off: the whole decrement is 0.04
    ((0.0, 0.0, 0.2), 2, True),  # ... but the body is where the step leaves it
    ((0.02, 0.0, 0.2), 2, False),  # the body 0.02 off: its part is 0.0012
    ((0.01, 0.0, 0.2), 2, True),  # 0.01 off: 0.0003
    ((0.0, 0.0, 0.4), 2, False),  # the whole decrement 0.16: the quadratic model not trusted
])
def test_the_body_converges_while_a_nuisance_may_still_move(theta, body, expected):
    """The body's part of the decrement is its Newton step in its own (profile) std, squared:
    ``(H⁻¹)_00`` is 1/3 here."""
    objective = _Quadratic(_H, np.zeros(3))
    assert converged(objective, np.array(theta), 1e-3, body) is expected


def test_a_nuisance_off_alone_leaves_the_body_converged():
    """A nuisance uncorrelated with the body, 0.2 off (decrement 0.04 > tol): the body's step
    is nil, so a fit for the body stops; one for every parameter does not; 0.5 off (0.25)
    is too far for the quadratic model to be trusted."""
    hessian = np.diag([4.0, 2.0, 1.0])
    objective = _Quadratic(hessian, np.zeros(3))
    assert converged(objective, np.array([0.0, 0.0, 0.2]), 1e-3, body=2)
    assert not converged(objective, np.array([0.0, 0.0, 0.2]), 1e-3)
    assert not converged(objective, np.array([0.0, 0.0, 0.5]), 1e-3, body=2)


def test_s_nearly_singular_is_told_by_its_eigenvalues():
    regular = np.tile(np.array([[1.0, 0.5], [0.5, 1.0]]), (10, 1, 1))
    assert not nearly_singular(regular)
    almost = regular.copy()
    eps = 0.1 * NEARLY_SINGULAR
    almost[3] = np.array([[1.0, 1.0 - eps], [1.0 - eps, 1.0]])  # eigenvalues 2 - eps and eps
    assert nearly_singular(almost)


EXACT = Vehicle(tolerances=Tolerances.none())


def _urban_window(start_s: float) -> tuple[np.ndarray, np.ndarray]:
    live = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=5, noise_std_mps2=MEMS_NOISE_MPS2,
                                vehicle=EXACT, drive_cycle_file="udds"))
    live.run(start_s)
    block = live.run(120.0)
    return block.accel_mps2, block.speed_mps


def test_an_urban_window_with_its_floors_at_zero_keeps_the_grid(monkeypatch):
    """An urban window (``udds`` from 270 s) fits both noise floors to zero: the road's mixed
    delays keep S regular, so the fit stays on the grid (before, it went on at every bin, at 3-4
    times the cost), and its estimate is the every-bin fit's within 0.01 std."""
    y, v = _urban_window(270.0)
    regrids = []
    regrid = VehicleSpectrum.regrid
    monkeypatch.setattr(VehicleSpectrum, "regrid", lambda self, *a: regrids.append(a[-1]) or regrid(self, *a))
    est = estimate(y, 100.0, EXACT, PipelineConfig(), v)
    assert 0.0 not in regrids  # (the cold start's coarse model is a regrid too)
    every = PipelineConfig(likelihood=dataclasses.replace(LikelihoodConfig(), grid_hz=0.0))
    exact = estimate(y, 100.0, EXACT, every, v)
    assert est.ok and exact.ok, (est.reason, exact.reason)
    assert max(est.refinement.noise_std_mps2) < 1e-3  # m/s²: MEMS noise is 0.025, fitted as none
    assert not est.refinement.every_bin and not exact.refinement.every_bin  # S regular: nor the next
    std = np.sqrt(np.diag(exact.covariance))
    assert np.all(np.abs(est.params - exact.params) < 0.01 * std), (est.params - exact.params) / std
    np.testing.assert_allclose(np.sqrt(np.diag(est.covariance)), std, rtol=0.01)


def test_a_window_after_noise_free_data_goes_back_to_the_grid():
    """A window started at every bin (its predecessor's S was nearly singular) whose own S is
    regular (10 % sensor noise) tells its successor to start on the grid again."""
    live = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=4, noise_std_mps2=0.05,
                                vehicle=EXACT))
    first = live.run(120.0).accel_mps2
    second = np.vstack([first[500:], live.run(5.0).accel_mps2])
    cold = estimate(first, 100.0, EXACT, PipelineConfig(), 100 / 3.6)
    assert cold.ok and not cold.refinement.every_bin
    singular = dataclasses.replace(cold, refinement=dataclasses.replace(cold.refinement, every_bin=True))
    warm = estimate(second, 100.0, EXACT, PipelineConfig(), 100 / 3.6, warm_start=singular)
    assert warm.ok and not warm.refinement.every_bin


def test_a_fit_stopped_before_it_converged_says_how_far_it_got():
    """The note names the iterations run of the limit and the Newton decrement left (it had
    said 'not converged in 100 iterations' after three)."""
    y, v = _urban_window(270.0)
    short = dataclasses.replace(LikelihoodConfig(), max_iter=1, second_start=False)
    est = estimate(y, 100.0, EXACT, PipelineConfig(likelihood=short), v)
    assert est.ok and est.refinement is not None
    note = next(n for n in est.notes if n.startswith("likelihood fit: not converged"))
    assert note.startswith(f"likelihood fit: not converged after {est.refinement.iterations} of 1 iterations "
                           "(Newton decrement "), note
    assert float(note.rsplit(" ", 1)[1].rstrip(")")) > LikelihoodConfig().tol


def test_a_warm_update_steps_a_falling_floor_without_a_trust_region(monkeypatch):
    """The first warm update after the stop at 400 s of ``udds`` (seed 3, the bench's): the
    last window's floor must fall from a share of 1e-2 towards zero. The line search's scoring
    reaches the trust region's optimum (within 0.02 std) in fewer iterations (4 against 6)."""
    live = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=3, noise_std_mps2=MEMS_NOISE_MPS2,
                                drive_cycle_file="udds"))
    live.run(400.0)
    block = live.run(130.0)
    windows = [(block.accel_mps2[i: i + 12000], block.speed_mps[i: i + 12000]) for i in (0, 500, 1000)]
    vehicle, cfg = Vehicle(), PipelineConfig()
    previous = estimate(windows[0][0], 100.0, vehicle, cfg, windows[0][1])
    previous = estimate(windows[1][0], 100.0, vehicle, cfg, windows[1][1], warm_start=previous)
    line = estimate(windows[2][0], 100.0, vehicle, cfg, windows[2][1], warm_start=previous)
    scoring = refine_module.scoring
    monkeypatch.setattr(refine_module, "scoring", lambda *a, near=False: scoring(*a, near=False))
    trust = estimate(windows[2][0], 100.0, vehicle, cfg, windows[2][1], warm_start=previous)
    assert line.ok and trust.ok, (line.reason, trust.reason)
    iterations = line.refinement.iterations, trust.refinement.iterations
    assert iterations[0] <= iterations[1] - 2, iterations
    std = np.sqrt(np.diag(trust.statistical_covariance))
    assert np.all(np.abs(line.params - trust.params) < 0.02 * std), (line.params - trust.params) / std
