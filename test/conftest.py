"""Shared fixtures and helpers for the core tests (no DDS needed here)."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.vehicle import Vehicle

TRUTH = np.array([1000.0, 2000.0, 1.2])  # Table 5-1: m_s, I_yy, l_f


@pytest.fixture
def vehicle() -> Vehicle:
    return Vehicle()


@pytest.fixture(autouse=True, scope="session")
def _single_blas_thread():
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        yield
