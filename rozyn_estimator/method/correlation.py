"""Correlation functions of the two accelerometer channels (thesis section 2-1).

Under broadband excitation the correlation function of the responses decays like the
system's free response (NExT). We use the multi-reference form: for each reference
channel ``j`` the sequence ``[R_fj(tau), R_rj(tau)]`` is one free decay of the system,
with front and rear on a **common** scale. (The thesis' per-channel autocorrelations,
each normalised by its own variance, distort the mode shapes; the pipeline keeps them
for the thesis method, computed from the same sums.)

``R_ij(tau) = sum_t y_i(t + tau) y_j(t)`` — statsmodels' ``ccovf(y_i, y_j)`` convention.
One FFT per channel and block serves all four channel pairs and every jackknife block,
which is why this is not four ``ccovf`` calls (the tests check the two agree).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as sfft

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.config import PipelineConfig
from rozyn_estimator.method.glitches import InputError


def block_bounds(n_samples: int, n_blocks: int) -> np.ndarray:
    """Start indices of ``n_blocks`` contiguous blocks covering ``n_samples``, plus the end."""
    return np.linspace(0, n_samples, n_blocks + 1).round().astype(int)


def correlation_sums(y: np.ndarray, max_lag: int, n_blocks: int = 1) -> np.ndarray:
    """Lagged products summed per block of start times.

    Args:
        y: (n_samples, m) demeaned signals (front, rear; or a full car's four corners).
        max_lag: largest lag [samples].
        n_blocks: split the start times ``t`` into this many contiguous blocks.

    Returns:
        (n_blocks, max_lag + 1, m, m) array ``S[b, tau, i, j] = sum over t in block b
        (with t + tau < n) of y[t + tau, i] * y[t, j]``. Summed over blocks it is the
        full-record correlation sum.
    """
    n, m = y.shape
    bounds = block_bounds(n, n_blocks)
    longest = int(np.max(np.diff(bounds)))
    nfft = sfft.next_fast_len(longest + max_lag, real=True)
    lead = np.zeros((n_blocks, nfft, m))  # y[t + tau]: the block and max_lag after it
    base = np.zeros((n_blocks, nfft, m))  # y[t]: the block only
    for b in range(n_blocks):
        a, e = bounds[b], bounds[b + 1]
        ext = y[a : min(e + max_lag, n)]
        lead[b, : ext.shape[0]] = ext
        base[b, : e - a] = y[a:e]
    spec_lead = sfft.rfft(lead, axis=1)
    spec_base = sfft.rfft(base, axis=1)
    cross = spec_lead[:, :, :, None] * np.conj(spec_base[:, :, None, :])
    return sfft.irfft(cross, n=nfft, axis=1)[:, : max_lag + 1]


def lag_range(cfg: PipelineConfig, fs_hz: float, v: AnyVehicle,
              speed_mps: float | None) -> tuple[int, int]:
    """(first, last) correlation lag in samples (the wheelbase delay skipped when asked)."""
    first_s = cfg.min_lag_s
    if cfg.skip_wheelbase_delay and speed_mps is not None and speed_mps > 0:
        first_s = max(first_s, v.wheelbase_m / speed_mps)
    if not first_s * fs_hz < 1e12:  # a speed so low that no window holds one wheelbase delay
        raise InputError(f"speed {speed_mps:.3g} m/s: the wheelbase delay {first_s:.3g} s exceeds any window")
    first = math.ceil(first_s * fs_hz - 1e-9)
    if cfg.correlation == "multi-reference":
        first = max(first, 1)  # lag 0 carries the sensor noise variance
    return first, first + round(cfg.max_lag_s * fs_hz)
