"""The full car's covariance on an intermittent road: the envelope's κ from the samples'
kurtosis, and where it raises the published variances (rozyn_estimator.method.vehicle_fit.intermittency)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import signal

from rozyn_estimator.method import METHODS
from rozyn_estimator.method.pipeline import estimate
from rozyn_estimator.method.vehicle_fit import intermittency, refine
from rozyn_estimator.method.vehicle_fit.intermittency import road_intermittency, road_itself
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


def _run(kind: str, seed: int, duration_s: float = 120.0) -> tuple[np.ndarray, refine.Refinement]:
    sim = SimConfig(model="full", full_vehicle=EXACT, road=RoadSpec(kind=kind, amplitudes="gaussian"),
                    speed_kmh=100.0, seed=seed)
    y = Simulation(sim).run(duration_s).accel_mps2
    y = y + np.random.default_rng([seed, 4]).standard_normal(y.shape) * 0.1 * y.std(axis=0)
    start = estimate(y, 100.0, EXACT, METHODS["rozyn"], 100 / 3.6).params
    ref = refine.refine(y, 100.0, EXACT, (0, 1, 2, 3), start, 100 / 3.6)
    assert ref.ok, ref.reason
    return y, ref


def test_the_intermittency_raises_the_roll_inertias_variance_on_a_laplace_road():
    """The roll inertia's information is nearly all the road's own (the tracks' difference),
    so an intermittent road raises its variance by about κ, the most of the five; the mass,
    the pitch inertia and l_f, measured mostly in the directions the road lacks, barely move
    (measured on 300 roads: they need no more). On a Gaussian road nothing moves."""
    laplace = np.array(_run("laplace", 4)[1].variance_factors)
    gaussian = np.array(_run("iso", 4)[1].variance_factors)
    assert laplace[1] > 1.4 and np.argmax(laplace) == 1, laplace
    assert np.all(laplace[[0, 2, 3]] < 1.1), laplace
    assert np.all(gaussian < 1.06), gaussian


def test_the_road_itself_is_the_models_road_without_the_periodograms_smoothing(monkeypatch):
    """What the intermittency scales: the road's part of S at the fit's frequencies,
    interpolated as the fit's S is, nearly of rank 2 (two tracks, four corners); the
    periodogram's expectation has more power where the road lacks it."""
    seen = {}

    def spy(objective, theta, *args):
        seen.update(objective=objective, theta=theta)
        return intermittency.variance_factors(objective, theta, *args)

    monkeypatch.setattr(refine, "variance_factors", spy)
    _run("iso", 3, duration_s=60.0)
    objective, theta = seen["objective"], seen["theta"]
    model = objective.model
    assert model.grid_hz > 0  # the interpolated case
    road = road_itself(objective, theta)
    floors = np.exp(theta[model.noise_slice]) + model.min_noise_psd
    exact = model.regrid(model.freq_hz, 0.0, 0.0).spectrum(theta, derivatives=False)[0] - np.eye(4) * floors
    assert np.abs(road - exact).max() < 1e-4 * np.abs(exact).max()
    own = np.linalg.eigvalsh(road)
    smoothed = np.linalg.eigvalsh(objective.at(theta)[1][model.index["ln_road"]])
    assert np.max(own[:, 1] / own[:, 3]) < 1e-3  # the two smallest: nearly nothing
    lacking = np.sum(own[:, :2], axis=1) / own[:, 3]
    assert np.median(np.sum(smoothed[:, :2], axis=1) / smoothed[:, 3]) > 1.5 * np.median(lacking)
