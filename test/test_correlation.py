from __future__ import annotations

import numpy as np
import pytest
from statsmodels.tsa.stattools import acf, ccovf

from rozyn_estimator.method.correlation import block_bounds, correlation_sums


@pytest.fixture
def signals():
    rng = np.random.default_rng(5)
    x = rng.standard_normal((3001, 2))
    x[:, 1] += 0.5 * np.roll(x[:, 0], 3)
    return x - x.mean(axis=0)


def test_matches_statsmodels_ccovf(signals):
    n, lags = signals.shape[0], 40
    sums = correlation_sums(signals, lags)[0] / n
    for i in range(2):
        for j in range(2):
            ref = ccovf(signals[:, i], signals[:, j], adjusted=False, demean=False)[: lags + 1]
            assert np.allclose(sums[:, i, j], ref, atol=1e-12), (i, j)


def test_thesis_acf_from_the_same_sums(signals):
    sums = correlation_sums(signals, 30)[0]
    for i in range(2):
        assert np.allclose(sums[:, i, i] / sums[0, i, i], acf(signals[:, i], nlags=30, fft=True))


def test_blocks_sum_to_the_whole(signals):
    whole = correlation_sums(signals, 25)[0]
    blocks = correlation_sums(signals, 25, n_blocks=7)
    assert blocks.shape == (7, 26, 2, 2)
    assert np.allclose(blocks.sum(axis=0), whole, atol=1e-9)
    bounds = block_bounds(signals.shape[0], 7)
    a, e = bounds[2], bounds[3]
    direct = sum(np.outer(signals[t + 4], signals[t]) for t in range(a, e))
    assert np.allclose(blocks[2, 4], direct)
