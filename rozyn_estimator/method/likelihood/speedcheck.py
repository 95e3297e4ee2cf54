"""Does the speed topic agree with the data? The data measure the speed themselves.

The rear wheel meets the front wheel's road a wheelbase later: the front/rear cross-spectrum
carries the delay ``τ = L / v`` in its phase (the model's ``R = [[1, φ̄], [φ, 1]]``,
``φ = E[e^(-iωτ)]``). A speed topic that reads ``r`` times the true speed puts that phase
at the wrong frequencies; the fit then bends the vehicle (a 10 % high speed moved l_f by
+16 %) or a sensor's timing calibration to follow it. :func:`check_speed` profiles the
likelihood over a scale ``c`` of the speed: the conditional likelihood at the fit's θ on a
grid of ``c``, then the fit again at the best ``c``. A gain of more than :data:`EVIDENCE_NATS`
(the 0.1 % point of a χ²₁, halved) names the speed. A rear sensor's delay shifts the same
phase (though not in the same way at every frequency): a small discrepancy names both.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

EVIDENCE_NATS = float(stats.chi2.isf(1e-3, 1)) / 2.0  # 5.4 nats: one parameter, p = 0.001
WRONG_RATIO = 1.25  # beyond this the speed is named alone (no sensor delay within tolerance does it)
SMALL_RATIO = 1.03  # below this the speed is as good as the data say
MIN_WINDOW_S = 30.0  # shorter windows are not checked: a few seconds of data misfit by chance, and
# the node's first updates after a start (its window filling) must not wait seconds for the check
_SCALES = np.geomspace(0.2, 5.0, 41)  # c: the data's speed over the topic's (1 is the middle one)
_NEAR = (1 / 1.2, 1 / 1.1, 1.1, 1.2)  # refits where the scan sees nothing: a fit follows a small error
_UNITS = (("km/h sent as m/s?", 3.6), ("mph sent as m/s?", 2.23694), ("m/s sent as km/h?", 1 / 3.6),
          ("km/h sent as mph?", 1.609344))


@dataclass(frozen=True)
class SpeedCheck:
    """The speed topic against the data: ``ratio`` the topic's speed over the data's,
    ``gain_nats`` how much better the data's speed explains the window (negative log
    likelihood, the fit redone)."""

    ratio: float
    gain_nats: float

    @property
    def wrong(self) -> bool:
        """The speed topic is wrong beyond doubt and beyond what a sensor's timing explains."""
        return self.gain_nats > EVIDENCE_NATS and not 1 / WRONG_RATIO < self.ratio < WRONG_RATIO

    @property
    def doubtful(self) -> bool:
        """The data prefer another speed by a small factor: the speed or a sensor's timing."""
        return self.gain_nats > EVIDENCE_NATS and not self.wrong and \
            not 1 / SMALL_RATIO < self.ratio < SMALL_RATIO

    def text(self) -> str:
        unit = next((hint for hint, r in _UNITS if abs(self.ratio / r - 1) < 0.05), "")
        said = f"the speed topic reads {self.ratio:.3g}× the speed the data show ({self.gain_nats:.0f} nats)"
        if self.wrong:
            return f"{said}{': ' + unit if unit else ''}; the fit needs the true speed: not used"
        return f"{said}, or a sensor's timing is off (the two shift the same phase): check both"


def check_speed(value_at: Callable[[float, np.ndarray], float],
                refit: Callable[[float, np.ndarray], tuple[np.ndarray, float] | None],
                theta: np.ndarray, value: float, window_s: float, rounds: int = 12) -> SpeedCheck:
    """The speed's check at the fit's optimum ``theta`` (its negative log likelihood ``value``)
    of a ``window_s`` window (none below :data:`MIN_WINDOW_S`): ``value_at(c, θ)`` the negative
    log likelihood with the speed scaled by ``c`` (inf where it has none), ``refit(c, θ)`` the
    fit from θ at that scale (its optimum and value).

    Each round scans the conditional likelihood over the scales at the current θ and refits
    at the best one: a fit bent by a wrong speed sees the true one's peak only roughly at
    first (km/h as m/s: 1.27× in the first round), so it scans again from the refit. A fit
    bent to a speed 10 % low prefers its own at fixed θ: where a scan sees nothing, refits at
    ±10 and ±20 % look (km/h as m/s stopped at 3.92× without them on 2 roads of 20)."""
    if window_s < MIN_WINDOW_S:
        return SpeedCheck(1.0, 0.0)
    scale, at, best_value = 1.0, theta, value
    for _ in range(rounds):
        with np.errstate(all="ignore"):
            conditional = np.array([_finite(value_at, scale * float(c), at) for c in _SCALES])
        best = int(np.argmin(conditional))
        # a fit bent to a speed a little off holds its own at fixed θ: refits near it look
        tried = [float(_SCALES[best])] if _SCALES[best] != 1.0 and conditional[best] < best_value - 1.0 \
            else list(_NEAR)
        found = [(c, f) for c in tried if (f := refit(scale * c, at)) is not None]
        c, fit = min(found, key=lambda cf: cf[1][1], default=(1.0, None))
        if fit is None or not fit[1] < best_value - 1.0:
            break
        scale, (at, best_value) = scale * c, fit
    if scale == 1.0:
        return SpeedCheck(1.0, 0.0)
    # the scale refined between its grid neighbours, the vehicle held
    step = math.log(_SCALES[1] / _SCALES[0])
    line = optimize.minimize_scalar(lambda ln_c: _finite(value_at, math.exp(ln_c), at),
                                    bounds=(math.log(scale) - step, math.log(scale) + step),
                                    method="bounded", options={"xatol": 1e-3})
    if line.success and line.fun <= best_value:
        scale, best_value = math.exp(line.x), float(line.fun)
    return SpeedCheck(1.0 / scale, value - best_value)


def _finite(value_at: Callable[[float, np.ndarray], float], c: float, theta: np.ndarray) -> float:
    """``value_at(c, θ)``, inf where the model has no finite likelihood (S singular)."""
    try:
        value = float(value_at(c, theta))
    except (ValueError, np.linalg.LinAlgError):
        return math.inf
    return value if math.isfinite(value) else math.inf
