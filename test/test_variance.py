"""The robust block jackknife covariance."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.method.modal_stage import jackknife_covariance


def replicates(g: int = 10, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    full = np.array([1000.0, 2000.0, 1.2])
    dev = rng.multivariate_normal([0, 0, 0], [[4.0, 3.0, 0.0], [3.0, 9.0, 0.0], [0.0, 0.0, 1e-6]], size=g)
    return full + dev, full


def test_equals_the_plain_jackknife_scale_for_a_normal_sample():
    reps, full = replicates(g=4000)
    cov, good = jackknife_covariance(reps, full)
    assert good == 4000
    # jackknife: (g - 1) * var of the replicates; MAD of a normal sample -> its std
    plain = (4000 - 1) * np.cov(reps, rowvar=False)
    assert np.sqrt(np.diag(cov)) == pytest.approx(np.sqrt(np.diag(plain)), rel=0.05)
    assert cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1]) == pytest.approx(0.5, abs=0.05)


def test_one_jumping_replicate_does_not_blow_the_scale():
    reps, full = replicates()
    calm, _ = jackknife_covariance(reps, full)
    reps[3, 0] += 1e4  # a near-degenerate mode made one replicate jump
    jumped, _ = jackknife_covariance(reps, full)
    assert jumped[0, 0] < 4 * calm[0, 0]
    assert (10 - 1) * np.var(reps[:, 0]) > 100 * calm[0, 0]  # the plain jackknife would report this


def test_too_few_successful_replicates_give_no_covariance():
    reps, full = replicates()
    reps[:4] = np.nan  # 6 of 10 succeeded (< 70 %)
    cov, good = jackknife_covariance(reps, full)
    assert cov is None and good == 6
    reps, full = replicates()
    reps[:3] = np.nan  # 7 of 10: enough
    cov, good = jackknife_covariance(reps, full)
    assert cov is not None and good == 7 and np.all(np.isfinite(cov))


def test_a_constant_parameter_has_zero_variance_not_nan():
    reps, full = replicates()
    reps[:, 2] = full[2]
    cov, _ = jackknife_covariance(reps, full)
    assert np.all(np.isfinite(cov)) and cov[2, 2] == 0.0 and cov[0, 2] == 0.0
