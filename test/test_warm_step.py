"""A warm start's first step (:meth:`Fits._warm_step`): taken as scipy's trust region takes
it, the proposed point evaluated at every bin at once; a start too far for it falls back."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rozyn_estimator.method.likelihood import HalfCarSpectrum, refine
from rozyn_estimator.method.likelihood.newton import Fits
from rozyn_estimator.vehicle import Vehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

SPEED = 100 / 3.6
START = np.array([1000.0, 2000.0, 1.2])


@pytest.fixture(scope="module")
def drive():
    sim = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=11, noise_std_mps2=0.05))
    return sim.run(125.0).accel_mps2


def consecutive(accel, window_s):
    """Two windows 5 s apart (the online estimator's consecutive updates) and the first's fit."""
    n = int(window_s * 100)
    first = refine(accel[:n], 100.0, Vehicle(), START, SPEED)
    assert first.ok, first.reason
    return accel[500: 500 + n], first


def _counted(monkeypatch):
    calls = []
    original = HalfCarSpectrum.spectrum

    def spectrum(self, *args, **kwargs):
        calls.append(kwargs.get("smooth", True))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(HalfCarSpectrum, "spectrum", spectrum)
    return calls


@pytest.mark.parametrize(("window_s", "iterations"), [(120.0, 1), (60.0, 2)])
def test_the_warm_step_ends_where_the_trust_region_does_with_fewer_evaluations(drive, monkeypatch, window_s,
                                                                              iterations):
    window, previous = consecutive(drive, window_s)
    calls = _counted(monkeypatch)
    stepped = refine(window, 100.0, Vehicle(), START, SPEED, warm=previous)
    direct = len(calls)
    monkeypatch.setattr(Fits, "_warm_step", lambda self, theta0: None)  # scipy's iterations only
    calls.clear()
    iterated = refine(window, 100.0, Vehicle(), START, SPEED, warm=previous)
    assert stepped.ok and iterated.ok
    assert stepped.iterations == iterated.iterations == iterations
    std = np.sqrt(np.diag(iterated.covariance))
    if iterations == 1:  # the very step scipy takes
        np.testing.assert_allclose(stepped.theta, iterated.theta, rtol=1e-9, atol=1e-12)
    assert np.all(np.abs(stepped.params - iterated.params) < 0.01 * std)
    np.testing.assert_allclose(stepped.covariance, iterated.covariance, rtol=0.01)
    assert direct < len(calls)


@pytest.mark.parametrize(("moves", "stepped"), [({3: 3.0}, True), ({0: 0.5, 1: 0.5, 3: 3.0, 4: 3.0}, False)])
def test_a_warm_start_far_off_goes_on_as_a_cold_one(drive, monkeypatch, moves, stepped):
    """The road 20 times as rough: the step is taken, but far from the optimum; the body and
    the noise moved as well: the Newton step is longer than the trust radius (not taken)."""
    window, previous = consecutive(drive, 60.0)
    cold = refine(window, 100.0, Vehicle(), START, SPEED)
    theta = previous.theta.copy()
    for k, move in moves.items():
        theta[k] += move
    taken = []
    original = Fits._warm_step

    def recorded(self, theta0):
        taken.append(original(self, theta0))
        return taken[-1]

    monkeypatch.setattr(Fits, "_warm_step", recorded)
    far = refine(window, 100.0, Vehicle(), START, SPEED, warm=dataclasses.replace(previous, theta=theta))
    assert cold.ok and far.ok
    assert (taken[0] is not None) == stepped and far.iterations > 2
    std = np.sqrt(np.diag(cold.covariance))
    assert np.all(np.abs(far.params - cold.params) < 0.01 * std)
