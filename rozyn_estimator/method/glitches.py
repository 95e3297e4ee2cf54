"""The window's checks (:func:`checked_window`) and glitch gating: samples no vehicle produced, found per
channel before either stage sees them.

A real accelerometer now and then sends a sample that is wildly wrong (a bus error, a
saturated conversion). One such sample dominates a window's correlations and spectra:
Rozyn's stage loses the modes and the refinement wanders. A sample is a *glitch* when it
is both

- extreme for its channel: more than :data:`GLITCH_Z` robust standard deviations
  (1.4826 × the median absolute deviation) from the channel's median, and
- isolated: just as far from the median of its :data:`NEIGHBOURS` neighbours on each
  side, in units of their own robust spread (at least the channel's).

Body accelerations are the response of a damped structure: a genuine large sample (a
pothole, a loud stretch of a Laplace road) has large neighbours and passes the second
test. In simulation a Gaussian road's 30 s window reaches ~5 robust deviations and a
strongly non-stationary Laplace road hundreds; the most isolated genuine samples (Laplace
roads sampled at 20 Hz, where neighbours are nearly independent) reach ~23 deviations of
their neighbours, at 50-100 Hz ~16. The threshold of 20 trades a rare gated genuine peak
(replaced by its neighbours: a small distortion) for catching glitches that still double
a window's power. A glitch is
replaced by its neighbours' median; runs of up to ``NEIGHBOURS - 1`` samples are still
outvoted by their neighbours. More than :data:`MAX_SHARE` of a channel's samples gated is
not a glitch but a faulty sensor: the window is refused.
"""

from __future__ import annotations

import math

import numpy as np

from rozyn_estimator.method.config import PipelineConfig

GLITCH_Z = 20.0  # robust standard deviations, for both tests
NEIGHBOURS = 4  # compared on each side of a candidate
MAX_SHARE = 0.01  # of a channel's samples, gated at most
_MAD_TO_STD = 1.4826  # a Gaussian's std per median absolute deviation


class GlitchError(ValueError):
    """Too many glitches on a channel: a faulty sensor (the window cannot be used)."""


def gate_glitches(
    accel: np.ndarray, names: tuple[str, ...] = ("front", "rear")
) -> tuple[np.ndarray, tuple[int, ...]]:
    """The (n, channels) finite samples with glitches replaced, and how many per channel.

    Raises:
        GlitchError: more than :data:`MAX_SHARE` of a channel's samples are glitches.
    """
    out = np.array(accel, dtype=float)
    counts = []
    for c, name in enumerate(names):
        with np.errstate(over="ignore", invalid="ignore"):  # see _glitches
            found, values = _glitches(out[:, c])
        if found.size > MAX_SHARE * out.shape[0]:
            raise GlitchError(
                f"{name} channel: {found.size} of {out.shape[0]} samples are isolated outliers "
                f"(> {GLITCH_Z:g} robust deviations): a faulty sensor"
            )
        out[found, c] = values
        counts.append(int(found.size))
    return out, tuple(counts)


def _glitches(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(indices of the glitches in ``x``, their neighbours' medians). Vectorised over the
    candidates only: the extreme samples are few, so a long window costs one median."""
    none = np.zeros(0, dtype=int)
    if x.size <= 2 * NEIGHBOURS:
        return none, x[none]
    centre = np.median(x)
    deviation = np.abs(x - centre)  # inf for a glitch near the float range's end: still one
    scale = _robust_std(deviation)
    candidates = np.flatnonzero(deviation > GLITCH_Z * scale)
    if candidates.size == 0:
        return none, x[none]
    offsets = np.r_[-NEIGHBOURS:0, 1:NEIGHBOURS + 1]
    at = candidates[:, None] + offsets
    inside = (at >= 0) & (at < x.size)
    neighbours = np.where(inside, x[np.clip(at, 0, x.size - 1)], np.nan)
    local = np.nanmedian(neighbours, axis=1)
    spread = _MAD_TO_STD * np.nanmedian(np.abs(neighbours - local[:, None]), axis=1)
    isolated = np.abs(x[candidates] - local) > GLITCH_Z * np.maximum(spread, scale)
    return candidates[isolated], local[isolated]


def _robust_std(x: np.ndarray) -> float:
    """1.4826 × the median absolute value of ``x`` (centred); where that is 0 (a coarsely
    quantised channel whose most common value is most samples), the smallest step from it."""
    deviation = np.abs(x)
    mad = _MAD_TO_STD * float(np.median(deviation))
    if mad > 0:
        return mad
    steps = deviation[deviation > 0]
    return float(steps.min()) if steps.size else 0.0


class InputError(Exception):
    """The window cannot be used (becomes a failed status)."""


def checked_window(
    y: np.ndarray, fs_hz: float, cfg: PipelineConfig, names: tuple[str, ...] = ("front", "rear")
) -> tuple[np.ndarray, tuple[int, ...]]:
    """(the window demeaned, with glitches gated; how many per channel); one column per name.

    Raises:
        InputError: the window cannot be used (the message says why).
    """
    if not (isinstance(fs_hz, int | float) and math.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(f"sample rate must be a positive number, got {fs_hz!r}")
    if y.ndim != 2 or y.shape[1] != len(names):
        raise InputError(f"expected accelerations of shape (n, {len(names)}), got {y.shape}")
    if not np.issubdtype(y.dtype, np.number) or np.iscomplexobj(y):
        raise InputError(f"expected real numbers, got dtype {y.dtype}")
    y = y.astype(float, copy=False)
    if not np.all(np.isfinite(y)):
        raise InputError(f"{int(np.sum(~np.isfinite(y)))} samples are NaN or Inf")
    if y.shape[0] < cfg.min_duration_s * fs_hz:
        raise InputError(f"window too short: {y.shape[0] / fs_hz:.2f} s < {cfg.min_duration_s:g} s")
    try:
        y, gated = gate_glitches(y, names)
    except GlitchError as exc:
        raise InputError(str(exc)) from None
    y = y - y.mean(axis=0)
    for i, name in enumerate(names):
        if not np.any(np.abs(y[:, i]) > 1e-9):
            raise InputError(f"{name} channel is constant: no vibration to identify")
    return y, gated
