"""Does the half-car model describe the data? A goodness-of-fit check of each refined update.

The statistic is :func:`rozyn_estimator.method.likelihood.whiteness.whiteness`: the window's
spectra whitened by the fitted model should be white, band by band (a complex-Wishart
likelihood ratio, χ² with the degrees of freedom the fit leaves). Misfit in a band means
power or coherence the model cannot produce there: a nonlinear suspension (asymmetric
dampers, progressive springs: their forces at combination frequencies are not driven
coherently by the road), a body that rolls or a sensor off the centreline (the roll mode's
power, incoherent between the channels), a time offset between the sensors (the
cross-spectrum's phase, growing with frequency). :func:`misfit` names the cause whose
pattern the misfit shows.

Noise floors. A floor the fit left at its lower boundary measures no noise (the simulator's
exact sensors): the check takes it away, and the dither (``whiteness``) stands for the
model's resolution there instead; the floor then absorbs nothing.

Calibrated sensors. When the sensors' delay or relative gain are calibrated (their
tolerance > 0), the fit absorbs them, so the spectra fit — but a calibrated value far
from the vehicle file's (``|estimate| > 4 std``) is a departure the user should know of,
and is reported with the cause it names.

How often it warns in the model and how surely it sees departures: docs/uncertainty.md
("When the model does not fit"), measured by ``test/test_model_check.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.method.likelihood.whiteness import Whiteness

ALPHA = 1e-3  # a p-value below this: the model does not fit (a WARN)
FITS = "fits"
NOT_COMPUTABLE = ("the model-fit check cannot be computed: the fitted spectral matrix is singular at some "
                  "frequencies (a channel fitted as noise-free)")
UNSTEADY = ("not checked: the window holds stops or pulling away, masked out (the check's statistic "
            "assumes a steady drive; on such windows it warned in 6 % of in-model urban windows)")


def unsteady_fit(freq_hz: np.ndarray) -> ModelFit:
    """The check's outcome on a window masked to its steady driving: not computed, no warning."""
    return ModelFit(math.nan, 0.0, math.nan, (float(freq_hz[0]), float(freq_hz[-1])), UNSTEADY)


@dataclass(frozen=True)
class ModelFit:
    """The check's outcome: the statistic, its p-value, the worst band, the verdict."""

    statistic: float
    dof: float  # the bands' components less what the fit absorbs (whiteness.absorbed)
    p_value: float
    worst_band_hz: tuple[float, float]
    verdict: str  # "fits", or what the data show and its likely cause
    dithered: float = 0.0  # the share of the band where the model's resolution set a dither

    @property
    def ok(self) -> bool:
        """Nothing to warn of: the model fits, or the window is not one the check can judge."""
        return self.verdict in (FITS, UNSTEADY)

    @property
    def misfit(self) -> bool:
        """The check ran and the model does not fit (not: it could not be computed)."""
        return self.verdict not in (FITS, NOT_COMPUTABLE, UNSTEADY)

    def to_dict(self) -> dict[str, object]:
        def number(x: float) -> float | None:  # JSON has no NaN (a check that cannot be computed)
            return x if math.isfinite(x) else None

        return {"statistic": number(self.statistic), "dof": number(self.dof), "p": number(self.p_value),
                "worst_band_hz": list(self.worst_band_hz), "verdict": self.verdict, "dithered": self.dithered}


def misfit(model: str, p: float, band: tuple[float, float], found: Whiteness, late: str) -> str:
    """What a misfit shows, and what to check: a likely cause only where its pattern singles
    one out (measured at 10 % sensor noise, each departure alone, 100 km/h):

    - two channels: the phase between them off, more so the higher the frequency (a time
      offset: the misfit ≥ 80 % in their coherence and in quadrature to the model's
      cross-spectrum, three times as much above the middle band as below);
    - two channels: their ratio off alike at every frequency (a gain: ≥ 80 % in the coherence,
      in phase with the model's cross-spectrum, no band with more than 40 % of it);
    - power the road does not drive coherently through the model: in the worst bands the
      coherence carries at most half its in-model share ((k - 1)/k: dampers twice as stiff in
      rebound gave a quarter of it on the half car; the values told wrong 1.3 to 2 times it);
    - otherwise a checklist, in the order the misfit's band suggests (the body modes below
      3 Hz: the suspension's values; wheel hop above 6 Hz: the tyres and unsprung masses).
    """
    per_band = np.asarray(found.per_band)
    half = per_band.size // 2
    coherence = per_band * found.cross_share
    cross = float(np.sum(coherence) / np.sum(per_band))
    worst = np.argsort(per_band)[-2:]
    worst_cross = float(np.sum(coherence[worst]) / np.sum(per_band[worst]))
    in_model = (found.channels - 1) / found.channels
    text = f"the {model} model does not fit the spectra (p = {p:.1g}; worst {band[0]:.2g}-{band[1]:.2g} Hz)"
    if found.channels == 2 and cross >= 0.8:
        quadrature = float(np.sum(coherence * found.quadrature) / np.sum(coherence))
        if quadrature >= 0.8 and np.sum(per_band[half:]) > 3.0 * np.sum(per_band[:half]):
            return (f"{text}: likely a time offset between the sensors (the phase between them is off, more "
                    f"so the higher the frequency): check {late}'s clock and stamps")
        if quadrature <= 0.2 and np.max(per_band) <= 0.4 * np.sum(per_band):
            return (f"{text}: likely the sensors' relative gain (their ratio is off alike at every "
                    "frequency): check their scale factors, or give their gains tolerances so that the "
                    "estimator calibrates them")
    if worst_cross <= 0.5 * in_model:
        return (f"{text}: the sensors carry power the road does not drive through the model: check for a "
                "nonlinear suspension (dampers stiffer in rebound than in compression) or motion the model "
                "lacks (a body that rolls under sensors off the centreline: use the full-vehicle model)")
    where = "the suspension's, tyres' and unsprung masses' values"
    if band[1] <= 3.0:
        where = "the suspension's stiffness and damping, then the tyres and unsprung masses"
    elif band[0] >= 6.0:
        where = "the tyres' stiffness and the unsprung masses, then the suspension's values"
    return (f"{text}: check the vehicle file's values ({where}; or give them tolerances so that the "
            "estimator calibrates them), the sensors' gains, positions and timing, and whether the "
            "suspension is nonlinear or the body moves in a way the model lacks (sensors off the centreline "
            "of a body that rolls: use the full-vehicle model)")


def neighbour_correlation(window_dft: np.ndarray) -> float:
    """κ = Σ_δ ρ_δ²: how many ordinates one independent one is worth under the taper."""
    w = window_dft / math.sqrt(float(np.sum(np.abs(window_dft) ** 2)))
    return float(np.sum(np.abs(np.correlate(w, w, "full")) ** 2))  # every lag δ, both signs
