"""Front and rear samples onto one uniform grid: pairing, resampling, anti-aliased decimation.

ROS-free. Sensors from the simulator share stamps and are paired sample by sample; real
sensors at other rates or with offset stamps are resampled (a faster one low-passed
first, so 1 kHz IMUs work as they are).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import signal

from rozyn_estimator.online.config import OnlineConfig

NS = 1_000_000_000


def pair_channels(
    front: tuple[np.ndarray, np.ndarray], rear: tuple[np.ndarray, np.ndarray], cfg: OnlineConfig
) -> tuple[np.ndarray, np.ndarray, float] | str:
    """Front/rear samples on one uniform grid: (stamps_ns, (n, 2) values, rate) or a reason.

    Aligned channels (the same stamps within ``pair_tolerance_s``, as from the sim) at
    most ``max_rate_hz`` fast are paired sample by sample. Otherwise both are resampled
    by linear interpolation onto a grid at ``rate_hz`` (default: the slower channel's
    rate, at most ``max_rate_hz``) over their overlap, a channel sampled faster than the
    grid first low-pass filtered below the grid's Nyquist frequency.
    """
    (tf, vf), (tr, vr) = front, rear
    if tf.size < 3 or tr.size < 3:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2)), 0.0
    dt_f, dt_r = _period(tf), _period(tr)
    tol = cfg.pair_tolerance_s * NS
    same_rate = abs(dt_f - dt_r) <= max(tol, 0.01 * min(dt_f, dt_r))
    slowest = NS / cfg.max_rate_hz
    if same_rate and not cfg.rate_hz and dt_f >= slowest * (1 - 1e-6):
        idx = np.clip(np.searchsorted(tr, tf), 1, tr.size - 1)
        nearest = np.where(np.abs(tr[idx - 1] - tf) <= np.abs(tr[idx] - tf), idx - 1, idx)
        match = np.abs(tr[nearest] - tf) <= tol
        if match.mean() > 0.95:
            t, a, b = tf[match], vf[match], vr[nearest[match]]
            if t.size > 2 and np.max(np.diff(t)) <= 1.5 * dt_f:
                return t, np.column_stack([a, b]), NS / dt_f
    dt = NS / cfg.rate_hz if cfg.rate_hz else max(dt_f, dt_r, slowest)
    lo, hi = max(tf[0], tr[0]), min(tf[-1], tr[-1])
    if hi - lo < 3 * dt:
        return "front and rear samples do not overlap in time"
    grid = hi - np.arange(int((hi - lo) // dt) + 1)[::-1] * dt
    grid_ns = np.round(grid).astype(np.int64)
    cols = [_resample(t, v, d, grid, dt) for t, v, d in ((tf, vf, dt_f), (tr, vr, dt_r))]
    return grid_ns, np.column_stack(cols), NS / dt


def _period(t: np.ndarray) -> float:
    """A channel's sample period [ns]: its median step, or its mean step when the stamps
    come in bursts so tight that the median would make a grid far denser than the samples."""
    median = float(np.median(np.diff(t)))
    mean = float(t[-1] - t[0]) / (t.size - 1)
    return median if mean <= 4 * median else mean


def _resample(t: np.ndarray, v: np.ndarray, dt_native: float, grid: np.ndarray, dt: float) -> np.ndarray:
    """One channel at the grid times; low-passed first if it is sampled faster than the grid."""
    if dt >= 1.5 * dt_native:
        native = np.arange(t[0], t[-1] + 0.5 * dt_native, dt_native)
        uniform = native.size == t.size and np.abs(native - t).max() < 0.01 * dt_native
        x = v if uniform else np.interp(native, t, v)  # a gap-free channel needs no interpolation
        q, first = dt / dt_native, (grid[0] - native[0]) / dt_native
        if abs(q - round(q)) < 1e-6 and abs(first - round(first)) < 0.01:
            # the grid is every q-th native sample (a 1 kHz IMU to 100 Hz): a polyphase FIR
            # computes only the samples kept, several times faster than filtering them all
            return _decimate(x, round(first), round(q), grid.size)
        sos = _lowpass(round(0.8 * dt_native / dt, 6))  # 0.8 x the grid's Nyquist
        if x.size > 3 * 2 * sos.shape[0] * 3:
            x = signal.sosfiltfilt(sos, x - x.mean()) + x.mean()
        return np.interp(grid, native, x)
    return np.interp(grid, t, v)


_FIR_HALF_OUT = 10  # the decimating FIR's half length, in output samples


def _decimate(x: np.ndarray, first: int, q: int, n: int) -> np.ndarray:
    """``n`` samples ``x[first], x[first + q], …``, low-passed (zero phase) below 0.8 x the
    output's Nyquist frequency. The filter reads samples beyond both ends where they exist
    and an odd reflection (as ``filtfilt`` pads; repeated when the window is shorter than
    the filter) where they do not."""
    half = _FIR_HALF_OUT * q
    last = first + (n - 1) * q
    lo, hi = max(first - half, 0), min(last + half, x.size - 1)
    seg = x[lo: hi + 1]
    need_lo, need_hi = half - (first - lo), half - (hi - last)
    if need_lo or need_hi:
        seg = np.pad(seg, (need_lo, need_hi), mode="reflect", reflect_type="odd")
    mean = seg.mean()
    y = signal.resample_poly(seg - mean, 1, q, window=_fir(q))
    return y[_FIR_HALF_OUT: _FIR_HALF_OUT + n] + mean


@functools.lru_cache(maxsize=8)
def _fir(q: int) -> np.ndarray:
    """Linear-phase low-pass for decimating by ``q``: passband flat to 0.6 x the output's
    Nyquist frequency (within 1 %), stop band (< 1e-3) from its Nyquist frequency."""
    return signal.firwin(2 * _FIR_HALF_OUT * q + 1, 0.8 / q, window=("kaiser", 8.0))


@functools.lru_cache(maxsize=8)
def _lowpass(cutoff: float) -> np.ndarray:
    """The anti-aliasing filter (cutoff as a share of the native Nyquist frequency); cached:
    designing it costs as much as running it on a window."""
    return signal.butter(8, cutoff, output="sos")
