"""What a window's speed says: the speed its road is seen at (:func:`window_speed`), how much
it varies (:func:`speed_spread`), and whether Rozyn's stage, which assumes a constant speed,
may stand in for a failed refinement (:data:`ROZYN_MAX_SPEED_VARIATION`)."""

from __future__ import annotations

import numpy as np

from rozyn_estimator.method.likelihood.road_input import driving_speed

ROZYN_MAX_SPEED_VARIATION = 0.1  # Rozyn's stage is a start only on a drive varying more than this


def window_speed(speed_mps: float | np.ndarray | None) -> tuple[float | None, float | np.ndarray | None]:
    """(mean speed, speed for the refinement), None where it is unknown."""
    if speed_mps is None:
        return None, None
    v = np.asarray(speed_mps, dtype=float)
    if v.size == 0 or not np.all(np.isfinite(v)) or not np.all(v >= 0) or not np.any(v > 0):
        return None, None
    return driving_speed(v), (float(v) if v.ndim == 0 else v)


def speed_spread(speed: float | np.ndarray | None) -> float:
    """(max - min) / driving speed of a window's speed (0: constant or unknown)."""
    v = np.atleast_1d(np.asarray(speed if speed is not None else 0.0, dtype=float))
    return float(np.ptp(v)) / driving_speed(v) if v.size > 1 and np.any(v > 0) else 0.0


def constant_speed_only(speed: float | np.ndarray | None) -> str | None:
    """Why Rozyn's stage alone gives no estimate of this window (None: it may): its speed varies
    by more than :data:`ROZYN_MAX_SPEED_VARIATION`."""
    spread = speed_spread(speed)
    if spread <= ROZYN_MAX_SPEED_VARIATION:
        return None
    return (f"Rozyn's method assumes a constant speed; the window's varies by {spread * 100:.0f} % (the "
            "likelihood refinement models a varying drive)")


def varying_drive(reason: str, speed: float | np.ndarray | None) -> str | None:
    """Why a window whose refinement failed (``reason``) has no estimate: its speed varies by more
    than :data:`ROZYN_MAX_SPEED_VARIATION`, so Rozyn's stage may not stand in (None: it may)."""
    spread = speed_spread(speed)
    if spread <= ROZYN_MAX_SPEED_VARIATION:
        return None
    return (f"likelihood refinement failed: {reason}; Rozyn's estimate is not published on a drive whose "
            f"speed varies by {spread * 100:.0f} % (its method assumes a constant speed)")
