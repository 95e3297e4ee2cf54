"""The refinement's caches (what depends only on a window's length and rate) never serve one
window's values to another: every cached result equals the one computed afresh.

Consecutive online windows share their length once the window is full; while it grows, and
on sensors whose stamps jitter, the length changes from one update to the next. The
taper and its DFT (``spectra``), the evaluation grid and its sparse maps (``grid``) and the
score's weights (``objective``) are cached; these tests interleave windows of other
lengths, rates, tapers, model settings and vehicles (wheelbase, sensor positions), then
compare every result with the same computation on empty caches, bit for bit. A warm update
keeps the last window's sensitivities (``sensitivity``) only for the same vehicle and
settings and a θ that barely moved.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import fft as sfft
from scipy.signal import windows

from rozyn_estimator.method.likelihood import (
    HalfCarSpectrum,
    LikelihoodConfig,
    WhittleObjective,
    covariance,
    grid,
    refine,
    spectra,
)
from rozyn_estimator.method.likelihood.spectra import fast_length, window_spectra
from rozyn_estimator.vehicle import Vehicle

from conftest import TRUTH

SPEED = 100 / 3.6
MOVED = dataclasses.replace(Vehicle(), wheelbase_m=2.7, sensor_front_offset_m=0.3, sensor_rear_offset_m=-0.6)
# (samples, rate [Hz], taper, model settings, vehicle): neighbours share all but one of them
CASES = [
    (12000, 100.0, 0.2, dict(road_shape_terms=4, grid_step=6), Vehicle()),
    (12000, 100.0, 0.1, dict(road_shape_terms=4, grid_step=6), Vehicle()),
    (12000, 100.0, 0.2, dict(road_shape_terms=2, grid_step=6), Vehicle()),
    (12000, 100.0, 0.2, dict(road_shape_terms=4, grid_step=1), Vehicle()),
    (12000, 100.0, 0.2, dict(road_shape_terms=4, grid_step=6, aliases=0), Vehicle()),
    (12000, 100.0, 0.2, dict(road_shape_terms=4, grid_step=6), MOVED),
    (11979, 100.0, 0.2, dict(road_shape_terms=4, grid_step=6), Vehicle()),
    (12000, 200.0, 0.2, dict(road_shape_terms=4, grid_step=6), Vehicle()),
    (3000, 100.0, 0.2, dict(road_shape_terms=4, grid_step=6), MOVED),
    (3000, 100.0, 0.0, dict(road_shape_terms=4, grid_step=6), MOVED),
]


def _clear() -> None:
    for cached in (grid._grid, grid._reduction, grid.interpolation, spectra._taper, covariance._partition):
        cached.cache_clear()


def _evaluate(n, fs, taper, settings, vehicle, accel):
    sp = window_spectra(accel[:n], fs, (0.5, min(15.0, 0.3 * fs)), taper)
    model = HalfCarSpectrum(vehicle, sp.freq_hz, fs, SPEED, estimate_waviness=True,
                            window_weights=sp.window_weights, **settings)
    theta = model.theta(TRUTH, 2e-3, np.array([3e-5, 5e-5]), waviness=2.1)
    theta[model.shape_slice] = 0.1
    S, dS = model.spectrum(theta)
    obj = WhittleObjective(model, sp)
    value, grad = obj.evaluate(theta)
    return [sp.window_dft, sp.periodogram, model.omega, model.shape_basis, model.kernel,
            model.reduction.to_bins.toarray(), S, dS, np.array([value]), grad, obj.fisher(theta),
            model.fine_spectrum(theta)]


def test_cached_window_geometry_is_each_windows_own():
    accel = np.random.default_rng(4).standard_normal((12000, 2))
    _clear()
    cached = [_evaluate(*case, accel) for case in CASES]  # each after the others' entries
    for case, got in zip(CASES, cached, strict=True):
        _clear()
        fresh = _evaluate(*case, accel)
        for a, b in zip(got, fresh, strict=True):
            assert a.shape == b.shape and np.array_equal(a, b), case


def test_the_cached_taper_is_the_window_own():
    """The taper's DFT of each length and share, against the formula computed here."""
    _clear()
    for n, taper in [(12000, 0.2), (11979, 0.2), (12000, 0.1), (3000, 0.2), (12000, 0.2)]:
        w = windows.tukey(n, taper)
        w = w / np.sqrt(np.mean(w * w))
        w_hat = sfft.fft(w) / n
        got = window_spectra(np.ones((n, 2)) + np.arange(n)[:, None] % 7, 100.0, (0.5, 15.0), taper)
        half = (got.window_dft.size - 1) // 2
        assert np.array_equal(got.window_dft, np.r_[w_hat[n - half:], w_hat[: half + 1]])
        assert np.sum(np.abs(got.window_dft) ** 2) >= 1.0 - 1e-4


def test_the_score_weights_follow_theta_and_the_combinations():
    accel = np.random.default_rng(5).standard_normal((6000, 2))
    sp = window_spectra(accel, 100.0, (0.5, 15.0), 0.2)
    model = HalfCarSpectrum(Vehicle(), sp.freq_hz, 100.0, SPEED, estimate_waviness=True,
                            window_weights=sp.window_weights, grid_step=6)
    obj = WhittleObjective(model, sp)
    rng = np.random.default_rng(6)
    theta = model.theta(TRUTH, 2e-3, np.array([3e-5, 5e-5]))
    moved = theta + 0.01
    combos, others = rng.standard_normal((2, 3, theta.size))
    for th, c in [(theta, combos), (moved, combos), (moved, others), (theta, others), (theta, combos)]:
        got = obj.score_weights(th, c)
        S, dS = model.spectrum(th)
        inv = np.linalg.inv(S)
        expected = inv[None] @ np.tensordot(c, dS, axes=1) @ inv[None]
        assert np.allclose(got, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("n", [3001, 5501, 9001, 11999, 12001, 12000])
def test_fast_length(n):
    m = fast_length(n)
    assert 0.98 * n <= m <= n
    for p in (2, 3, 5, 7, 11):
        while m % p == 0:
            m //= p
    assert m == 1
    assert fast_length(12000) == 12000 and fast_length(3000) == 3000


def test_the_refinement_uses_the_newest_samples_of_a_fast_length():
    """A window of 9 001 samples is refined on its newest 9 000, bit for bit."""
    from sim_node.road import RoadSpec
    from sim_node.simulation import SimConfig, Simulation

    block = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=3, duration_s=90.01,
                                 noise_std_mps2=0.05)).run(90.01)
    accel, speed = block.accel_mps2, block.speed_mps
    assert accel.shape[0] == 9001 and fast_length(9001) == 9000
    cfg = LikelihoodConfig()
    whole = refine(accel, 100.0, Vehicle(), TRUTH, speed, cfg)
    newest = refine(accel[1:], 100.0, Vehicle(), TRUTH, speed[1:] if np.ndim(speed) else speed, cfg)
    assert whole.ok and np.array_equal(whole.params, newest.params)
    assert np.array_equal(whole.covariance, newest.covariance)
    assert math.isfinite(whole.neg_log_likelihood) and whole.neg_log_likelihood == newest.neg_log_likelihood


def test_a_warm_update_keeps_the_sensitivities_only_where_they_hold():
    """The next window keeps the last one's sensitivities (θ barely moved); another vehicle (its
    sensors elsewhere, its tolerances), other settings or a θ moved by more than 0.01 get their
    own, equal to those computed with nothing to keep."""
    from sim_node.road import RoadSpec
    from sim_node.simulation import SimConfig, Simulation

    block = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=3, duration_s=65.0,
                                 noise_std_mps2=0.05)).run(65.0)
    accel, speed = block.accel_mps2, float(np.mean(block.speed_mps))
    first, nxt = accel[:6000], accel[500:6500]
    cfg = LikelihoodConfig()
    last = refine(first, 100.0, Vehicle(), TRUTH, speed, cfg)
    assert last.ok and last.sensitivities is not None and set(last.sensitivities.per_unit) == {"wheelbase_m"}
    kept = refine(nxt, 100.0, Vehicle(), TRUTH, speed, cfg, warm=last)
    assert kept.sensitivities is last.sensitivities
    taken = last.sensitivities
    moved_body = dataclasses.replace(taken, body=taken.body + np.array([0.02, 0.0, 0.0]))
    tolerances = dataclasses.replace(Vehicle().tolerances, wheelbase_m=0.01)
    looser = dataclasses.replace(Vehicle(), tolerances=tolerances)
    for vehicle, settings, warm in [
        (MOVED, cfg, last),  # another sensor layout and wheelbase
        (looser, cfg, last),  # other tolerances
        (Vehicle(), dataclasses.replace(cfg, block_weight=0.4), last),  # other settings
        (Vehicle(), cfg, dataclasses.replace(last, sensitivities=moved_body)),  # θ moved
    ]:
        got = refine(nxt, 100.0, vehicle, TRUTH, speed, settings, warm=warm)
        nothing_kept = dataclasses.replace(warm, sensitivities=None)
        fresh = refine(nxt, 100.0, vehicle, TRUTH, speed, settings, warm=nothing_kept)
        assert got.ok and got.sensitivities is not warm.sensitivities
        assert got.sensitivities.vehicle == vehicle and got.sensitivities.config == settings
        for key, value in fresh.contributions.items():
            assert np.array_equal(got.contributions[key], value), key
        assert np.array_equal(got.covariance, fresh.covariance)
    # what keeping them costs: the wheelbase's part within 5 % of the window's own, the std within 0.1 %
    own = refine(nxt, 100.0, Vehicle(), TRUTH, speed, cfg, warm=dataclasses.replace(last, sensitivities=None))
    assert np.allclose(kept.contributions["wheelbase_m"], own.contributions["wheelbase_m"], rtol=0.05)
    assert np.allclose(np.diag(kept.covariance), np.diag(own.covariance), rtol=2e-3)
