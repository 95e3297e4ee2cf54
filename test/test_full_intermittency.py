"""The full car's covariance on an intermittent road: the envelope's κ from the samples'
kurtosis, and where it raises the published variances (rozyn_estimator.method.full.blocks)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import signal

from rozyn_estimator.method import METHODS
from rozyn_estimator.method.full import estimate_full
from rozyn_estimator.method.full.blocks import road_intermittency
from rozyn_estimator.method.full.refine import refine_full
from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

EXACT = dataclasses.replace(FullVehicle(), tolerances=FullTolerances.none())


def _band_limited(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """(n, k) correlated Gaussian channels, band-limited like a body's accelerations."""
    b, a = signal.butter(4, [0.02, 0.3], btype="band")
    common = rng.standard_normal((n, 1))
    return signal.lfilter(b, a, common + 0.5 * rng.standard_normal((n, k)), axis=0)


def test_a_gaussian_road_has_no_intermittency():
    x = _band_limited(np.random.default_rng(1), 12_000, 4)
    assert road_intermittency(x, np.zeros(4), 0.2) == pytest.approx(1.0, abs=0.06)


def test_a_patchy_roads_kappa_is_its_envelopes_and_the_noise_is_taken_out():
    rng = np.random.default_rng(2)
    n, patch = 24_000, 400
    y = rng.gamma(1.0, 1.0, n // patch)  # Laplace, nu = 1: kappa = 2 on average
    envelope = np.repeat(np.sqrt(y), patch)[:, None]
    road = envelope * _band_limited(rng, n, 4)
    edge = int(0.1 * n) + 1
    inner = np.repeat(y, patch)[edge: n - edge]
    truth = np.mean(inner**2) / np.mean(inner) ** 2  # this drive's own E[Y²]/E[Y]²
    assert road_intermittency(road, np.zeros(4), 0.2) == pytest.approx(truth, rel=0.1)
    noise = rng.standard_normal(road.shape) * road.std(axis=0)  # half of each channel's power
    noisy = road + noise
    assert road_intermittency(noisy, np.full(4, 0.5), 0.2) == pytest.approx(truth, rel=0.15)
    assert road_intermittency(noisy, np.zeros(4), 0.2) < 1.0 + 0.6 * (truth - 1.0)  # noise dilutes κ


def test_bad_samples_say_nothing_rather_than_a_made_up_kappa():
    assert road_intermittency(np.zeros((5000, 4)), np.zeros(4), 0.2) == 1.0
    assert road_intermittency(np.ones((5000, 2)), np.ones(2), 0.2) == 1.0  # all noise: no road part


def _factors(kind: str, seed: int) -> np.ndarray:
    sim = SimConfig(model="full", full_vehicle=EXACT, road=RoadSpec(kind=kind, amplitudes="gaussian"),
                    speed_kmh=100.0, seed=seed)
    y = Simulation(sim).run(120.0).accel_mps2
    y = y + np.random.default_rng([seed, 4]).standard_normal(y.shape) * 0.1 * y.std(axis=0)
    start = estimate_full(y, 100.0, EXACT, METHODS["rozyn"], 100 / 3.6).params
    ref = refine_full(y, 100.0, EXACT, (0, 1, 2, 3), start, 100 / 3.6, LikelihoodConfig(block_weight=0.0))
    assert ref.ok, ref.reason
    return np.array(ref.variance_factors)


def test_the_intermittency_raises_the_roll_inertias_variance_on_a_laplace_road():
    """The roll inertia's information is nearly all the road's (the tracks' difference), so
    an intermittent road raises its variance by about κ, and the most of the five; the
    mass's, measured partly against the noise floors (where the periodogram's averaging
    leaves some road power too), by less than half as much. On a Gaussian road nothing
    moves (the time blocks are off here: what shows is the intermittency alone)."""
    laplace, gaussian = _factors("laplace", 4), _factors("iso", 4)
    assert laplace[1] > 1.4 and np.argmax(laplace) == 1, laplace
    assert laplace[0] - 1.0 < 0.5 * (laplace[1] - 1.0), laplace
    assert np.all(gaussian < 1.06), gaussian
