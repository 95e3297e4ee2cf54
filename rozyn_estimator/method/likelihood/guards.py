"""Guards of a fit's optimum shared by the refinement and the calibration: a noise floor run
aground revived (:func:`aground`), a step backtracked until it does not lose (:func:`backtracked`),
where a floor counts as zero (:data:`NOISE_AT_ZERO`) and when floors at zero make S singular
(:func:`singular_floors`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np

NOISE_AT_ZERO = 1e-5  # a noise floor below this share of its channel's band power: noise-free, held
# S nearly singular: its smallest eigenvalue below this share of its largest at some frequency.
# Measured at the fit's optimum: noise-free at a constant speed (floors at zero) 1.3e-5, MEMS noise
# at a constant speed 7e-5 (the grid serves it), urban windows with both floors at zero 2e-3 to
# 7e-3 (the road's delays mixed: the grid's estimates within 0.0005 std of every bin's)
NEARLY_SINGULAR = 1e-4
_HALVINGS = 4  # backtracking of a step when it does not lower ℓ

# a floor's share of its channel's power where the slope at zero is read: an urban window's
# MEMS noise (1 % of its power) gained 0.07 nats at 1e-4, 0.7 at 1e-3 and 3 at 1e-2 (its floor
# at zero); on noise-free data the slope's spread there is about 0.4 nats
_PROBE_SHARE = 1e-2
_REVIVE_SHARES = 10.0 ** np.arange(-8, 0)  # the floors tried for one run aground, share of its power


class FloorProbe(Protocol):
    """What :func:`aground` asks of an objective (the Whittle objective's methods)."""

    def fun(self, theta: np.ndarray) -> float: ...

    def jac(self, theta: np.ndarray) -> np.ndarray: ...

    def floor_values(self, theta: np.ndarray, channel: int, floors: np.ndarray, at: int) -> np.ndarray: ...


def aground(objective: FloorProbe, theta: np.ndarray, value: float, noise: slice,
            power: np.ndarray) -> np.ndarray | None:
    """A start for a fit whose noise floor ran aground: θ with that floor at the best of a few
    levels, where that beats the fit's optimum ``value`` at ``theta`` (else None).

    A floor is its log in θ, and at a floor far below its channel's power the likelihood's
    gradient in it vanishes: a fit that wandered there (a poor start, on noisy data) cannot
    come back, and ends in a wrong basin with that channel noise-free (the model check then
    rightly warns). Such a floor's likelihood still falls as the floor itself grows (the
    gradient in the floor, not its log, is negative where raising it to :data:`_PROBE_SHARE`
    of its channel's power would gain a nat): only those are tried, so noise-free data cost
    one gradient. The levels are scored together from the evaluation at θ
    (``floor_values``); the one chosen is evaluated afresh, and is where the fit goes on."""
    floors = np.exp(theta[noise])
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = objective.jac(theta)[noise] / floors  # ∂ℓ/∂n: the chain rule's factor n taken out
    stuck = np.flatnonzero((floors < 1e-4 * power) & (slope * _PROBE_SHARE * power < -1.0))
    start, best = None, value
    for i in stuck:
        levels = _REVIVE_SHARES * power[i]
        values = objective.floor_values(theta, int(i), levels, noise.start + int(i))
        if not np.any(values < best):
            continue
        trial = theta.copy()
        trial[noise.start + i] = math.log(levels[int(np.argmin(values))])
        f = objective.fun(trial)
        if np.isfinite(f) and f < best:
            start, best = trial, f
    return start


def backtracked(
    posterior: Callable[[np.ndarray], float], point: np.ndarray, step: np.ndarray, value: float
) -> np.ndarray:
    """``point + step``, halved until the ``posterior``'s ℓ does not exceed ``value`` (at most a
    few times); ``point`` when none does."""
    for _ in range(_HALVINGS):
        if posterior(point + step) <= value:
            return point + step
        step = 0.5 * step
    return point


def nearly_singular(S: np.ndarray) -> bool:
    """S (K, k, k) has a frequency where it is nearly singular (:data:`NEARLY_SINGULAR`): where
    floors at zero (:func:`singular_floors`) leave it so, the grid's small interpolation errors
    matter. A varying drive's road reaches the axles at a mixture of delays, which decorrelates
    them: its floors at zero leave S well conditioned."""
    eigenvalues = np.linalg.eigvalsh(S)
    return bool(np.min(eigenvalues[:, 0] / eigenvalues[:, -1]) < NEARLY_SINGULAR)


def singular_floors(shares: np.ndarray, two_tracks: bool) -> bool:
    """More channels noise-free (``shares``: each floor's share of its channel's power) than
    the road has inputs (one track, or two): S is then singular but for the interpolation's
    errors. One floor at zero among the half car's two leaves S as well conditioned as its
    other floor (an urban window's MEMS noise is about 1 % of its power, and its floor often runs
    to zero within its std): the grid stands there."""
    return int(np.count_nonzero(shares < NOISE_AT_ZERO)) > (2 if two_tracks else 1)
