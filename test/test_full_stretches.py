"""A varying drive's stretches in the full car's covariance (rozyn_estimator.method.vehicle_fit.stretches):
the samples grouped by speed, and the factors they give the published variances."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rozyn_estimator.method import METHODS
from rozyn_estimator.method.likelihood.road_input import DRIVING_MPS
from rozyn_estimator.method.likelihood.spectra import taper_window
from rozyn_estimator.method.pipeline import estimate
from rozyn_estimator.method.vehicle_fit import intermittency, refine, stretches
from rozyn_estimator.method.vehicle_fit.stretches import drive_stretches
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

EXACT = dataclasses.replace(FullVehicle(), tolerances=FullTolerances.none())
FS = 100.0
TAPERED = taper_window(12_000, 0.1) ** 2  # a 120 s window's sample weights, tapered


def test_a_steady_speed_has_no_stretches_and_a_stop_belongs_to_none():
    assert drive_stretches(2.8, np.full(12_000, 20.0), FS, TAPERED) is None
    t = np.arange(12_000) / FS
    speed = np.where(t < 50, 10.0, 25.0)
    speed[(t > 55) & (t < 75)] = 0.0  # a stop between the two speeds
    parts = drive_stretches(2.8, speed, FS, TAPERED)
    assert parts is not None and parts.parts.shape[0] >= 2
    assert not np.any(parts.parts.sum(axis=0) > 1)  # each delay bin in one stretch
    stopped = (speed < DRIVING_MPS).mean()
    assert 0.6 < parts.time.sum() < 1.0 - 0.5 * stopped  # the stop (and the pulling away) in none
    assert parts.flat.sum() == pytest.approx(parts.time.sum(), abs=0.1)
    for shares in (parts.time, parts.fourth, parts.flat):
        assert np.all(shares > 0)


def _refined(speed: np.ndarray | float, y: np.ndarray) -> refine.Refinement:
    start = estimate(y, FS, EXACT, METHODS["rozyn"], 20.0).params
    ref = refine.refine(y, FS, EXACT, (0, 1, 2, 3), start, speed)
    assert ref.ok, ref.reason
    return ref


def test_stretches_alike_give_the_steady_drives_factors():
    """A speed given per sample that barely varies is a varying drive to the model (its delays
    in 64 bins, in five stretches), but every stretch holds the same road: the factors must be
    the steady formula's, ``1 + (κ - 1) ρ`` (the stretched sum reduces to it exactly)."""
    sim = Simulation(SimConfig(model="full", full_vehicle=EXACT, road=RoadSpec(amplitudes="gaussian"),
                               speed_kmh=72.0, seed=5))
    y = sim.run(120.0).accel_mps2
    y = y + np.random.default_rng(5).standard_normal(y.shape) * 0.1 * y.std(axis=0)
    ripple = 20.0 * (1.0 + 1e-6 * np.sin(np.arange(y.shape[0]) / 50.0))
    assert drive_stretches(EXACT.wheelbase_m, ripple, FS, TAPERED) is not None
    steady, stretched = _refined(20.0, y), _refined(ripple, y)
    np.testing.assert_allclose(stretched.variance_factors, steady.variance_factors, rtol=0.03)


def _two_speeds(tmp_path, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(speed per sample, accelerations with noise) of a 120 s drive: half at 8 m/s, half at
    25 m/s, a stop between."""
    cycle = np.array([[0, 8.0], [55, 8.0], [58, 0.0], [66, 0.0], [72, 25.0], [130, 25.0]])
    path = tmp_path / "two_speeds.csv"
    path.write_text("time_s,speed_mps\n" + "".join(f"{t:g},{v:g}\n" for t, v in cycle))
    sim = Simulation(SimConfig(model="full", full_vehicle=EXACT, road=RoadSpec(amplitudes="gaussian"),
                               seed=seed, drive_cycle_file=str(path)))
    block = sim.run(120.0)
    noise = np.random.default_rng(seed).standard_normal(block.accel_mps2.shape) * 0.02
    return block.speed_mps, block.accel_mps2 + noise


def test_a_drive_at_two_speeds_raises_the_roll_more_than_the_heave(tmp_path, monkeypatch):
    """Half the window at 8 m/s, half at 25 m/s (a stop between, masked): the tracks' difference,
    whose power grows at the low speed (their coherence falls with f/v), raises the roll
    inertia's and the lateral CoG's variance well above the mass's, which two stretches of
    different shape need not raise at all (the score's kernels are indefinite): 1.28 and 1.52
    against 1.00 with the stretches ramped in and out over 3 s (above 1.3 and 1.5 cut square).
    The published factors are the larger of these and the samples' kurtosis's."""
    seen = []

    def spy(*args, **kwargs):
        seen.append(stretches.stretched_factors(*args, **kwargs))
        return seen[-1]

    monkeypatch.setattr(intermittency, "stretched_factors", spy)
    published = np.array(_refined(*_two_speeds(tmp_path, 6)).variance_factors)
    stretched = seen[-1]
    assert np.all(stretched >= 1.0), stretched
    assert stretched[1] > 1.2 * stretched[0] and stretched[4] > 1.2 * stretched[0], stretched
    assert np.all(published >= stretched - 1e-12) and np.any(published > stretched), (published, stretched)


def test_the_factors_over_every_third_frequency_are_the_whole_sums(tmp_path, monkeypatch):
    """The factors' sums run over the Fisher information's frequencies (every third, each
    standing for its neighbours): they are smooth in frequency, so they agree with the sums over
    every frequency (measured within 0.03 % on urban windows) at a third of the work."""
    calls = []
    real = intermittency.intermittency_factors

    def spy(objective, *args, **kwargs):
        calls.append((objective, args, kwargs))
        return real(objective, *args, **kwargs)

    monkeypatch.setattr(intermittency, "intermittency_factors", spy)
    _refined(*_two_speeds(tmp_path, 7))
    objective, args, kwargs = calls[-1]
    at, counts = objective.sampled_frequencies()
    assert at.size < 0.4 * objective.counts.size and counts.sum() == pytest.approx(objective.counts.sum())
    sampled = real(objective, *args, **kwargs)
    every = np.arange(objective.counts.size)
    monkeypatch.setattr(objective, "sampled_frequencies", lambda: (every, objective.counts))
    whole = real(objective, *args, **kwargs)
    assert np.max(whole) > 1.1, whole  # the factors are not trivially one
    np.testing.assert_allclose(sampled, whole, rtol=1e-3)
