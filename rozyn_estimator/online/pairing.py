"""The accelerometers' samples onto one uniform grid: pairing, resampling, anti-aliased decimation.

ROS-free; the half car's front and rear channels or the full car's three or four corners.
Sensors from the simulator share stamps and are paired sample by sample; real
sensors at other rates or with offset stamps are resampled (a faster one low-passed
first, so 1 kHz IMUs work as they are).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from scipy import signal

from rozyn_estimator.online.config import OnlineConfig

NS = 1_000_000_000


def pair_channels(
    front: tuple[np.ndarray, np.ndarray], rear: tuple[np.ndarray, np.ndarray], cfg: OnlineConfig
) -> tuple[np.ndarray, np.ndarray, float] | str:
    """Front/rear samples on one uniform grid: (stamps_ns, (n, 2) values, rate) or a reason
    (:func:`align_channels` of the half car's two channels)."""
    return align_channels((front, rear), cfg)


def align_channels(
    samples: Sequence[tuple[np.ndarray, np.ndarray]], cfg: OnlineConfig
) -> tuple[np.ndarray, np.ndarray, float] | str:
    """Samples of k channels on one uniform grid: (stamps_ns, (n, k) values, rate) or a reason.

    Aligned channels (each sample of the first has one of every other channel within
    ``pair_tolerance_s``, as from the sim) at most ``max_rate_hz`` fast are paired sample
    by sample. Otherwise all are resampled by linear interpolation onto a grid at
    ``rate_hz`` (default: the slowest channel's rate, at most ``max_rate_hz``) over their
    overlap, a channel sampled faster than the grid first low-pass filtered below the
    grid's Nyquist frequency.

    Args:
        samples: per channel (stamps_ns, values), each in stamp order.
        cfg: the tolerance and rates.
    """
    if any(t.size < 3 for t, _ in samples):
        return np.zeros(0, dtype=np.int64), np.zeros((0, len(samples))), 0.0
    periods = [_period(t) for t, _ in samples]
    (tf, vf), dt_f = samples[0], periods[0]
    tol = cfg.pair_tolerance_s * NS
    same_rate = max(periods) - min(periods) <= max(tol, 0.01 * min(periods))
    slowest = NS / cfg.max_rate_hz
    if same_rate and not cfg.rate_hz and dt_f >= slowest * (1 - 1e-6):
        match = np.ones(tf.size, dtype=bool)
        nearest = []
        for tr, _ in samples[1:]:
            idx = np.clip(np.searchsorted(tr, tf), 1, tr.size - 1)
            near = np.where(np.abs(tr[idx - 1] - tf) <= np.abs(tr[idx] - tf), idx - 1, idx)
            match &= np.abs(tr[near] - tf) <= tol
            nearest.append(near)
        if match.mean() > 0.95:
            t = tf[match]
            cols = [vf[match], *(v[near[match]] for (_, v), near in zip(samples[1:], nearest, strict=True))]
            if t.size > 2 and np.max(np.diff(t)) <= 1.5 * dt_f:
                return t, np.column_stack(cols), NS / dt_f
    dt = NS / cfg.rate_hz if cfg.rate_hz else max(*periods, slowest)
    lo, hi = max(t[0] for t, _ in samples), min(t[-1] for t, _ in samples)
    if hi - lo < 3 * dt:
        return "front and rear samples do not overlap in time" if len(samples) == 2 else \
            "the accelerometers' samples do not overlap in time"
    grid = hi - np.arange(int((hi - lo) // dt) + 1)[::-1] * dt
    grid_ns = np.round(grid).astype(np.int64)
    cols = [_resample(t, v, d, grid, dt) for (t, v), d in zip(samples, periods, strict=True)]
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
