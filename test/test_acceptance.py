"""Issue 2's acceptance over 100 seeds each (a few seconds each on 2 cores).

The thesis' chapter 5 conditions: ISO 8608 class A, 100 km/h, 100 s at 100 Hz.
"""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.tools.trial.run import run_trials
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.tools.trial.summary import summarise

from conftest import TRUTH

SEEDS = range(501, 601)  # not the seeds the defaults were explored on


def _results(spec):
    return list(run_trials(spec, SEEDS, jobs=2))


def test_iso_fixed_amplitudes_reproduces_the_thesis():
    s = summarise(_results(TrialSpec(road="iso", amplitudes="fixed")))
    assert s.failures <= 1
    assert np.all(np.abs(s.mean / TRUTH - 1) <= 0.02)
    assert np.all(s.within_6pct * (s.n - s.failures) >= 95)


def test_laplace_road_rarely_fails():
    s = summarise(_results(TrialSpec(road="laplace", laplace_nu=1.0)))
    assert s.failures <= 2
    assert np.all(np.abs(s.mean / TRUTH - 1) <= 0.10)  # the thesis: within about 5 %


def test_reported_variance_is_calibrated_on_gaussian_roads():
    """Mean reported variance over 100 independent roads vs the variance of the
    estimates: ratio within 0.5-2 for each parameter."""
    results = [r for r in _results(TrialSpec(road="iso", amplitudes="gaussian")) if r.estimate.ok]
    assert len(results) >= 95
    params = np.array([r.estimate.params for r in results])
    reported = np.array([np.diag(r.estimate.covariance) for r in results])
    ratio = reported.mean(axis=0) / params.var(axis=0, ddof=1)
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio


@pytest.mark.slow
@pytest.mark.parametrize("speed_kmh", [30.0, 60.0])
def test_variance_is_never_optimistic_at_other_speeds(speed_kmh):
    """Away from 100 km/h the block jackknife errs on the safe side: it may report up to
    about 3x the variance (the Efron-Stein excess of a strongly nonlinear estimator) but
    must never under-report."""
    results = list(run_trials(TrialSpec(amplitudes="gaussian", speed_kmh=speed_kmh, duration_s=120.0),
                              range(1, 201), jobs=2))
    ok = [r for r in results if r.estimate.ok]
    assert len(ok) >= 196
    params = np.array([r.estimate.params for r in ok])
    reported = np.array([np.diag(r.estimate.covariance) for r in ok])
    ratio = reported.mean(axis=0) / params.var(axis=0, ddof=1)
    assert np.all((ratio > 0.8) & (ratio < 3.5)), ratio
