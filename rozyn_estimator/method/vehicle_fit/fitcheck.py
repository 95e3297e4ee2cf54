"""Does the vehicle model describe the data? The goodness-of-fit check of each refined update.

The check on k channels, either car (:mod:`rozyn_estimator.method.likelihood.fitcheck` holds
its verdicts): the statistic is :func:`rozyn_estimator.method.likelihood.whiteness.whiteness`
with the road's inputs (rank 2: the full car's two tracks; 1: the half car's one), over the
fit's means of neighbouring bins (a mean counts as the bins it holds). Misfit means power or
coherence between the channels the model cannot produce: suspension or tyre values off the
vehicle file's or a sensor's gain or timing beyond what their tolerances let the calibration
absorb, a nonlinear suspension (its forces at combination frequencies), a body that is not
rigid between the sensors.

Noise-free sensors. Four exact sensors on a rigid body span three motions: the fitted S is
then singular in the fourth direction. Floors the fit left at zero are taken away and the
dither (``whiteness``) fills the directions the road does not drive, to the model's
resolution, so the check has its distribution there too.

How often it warns in the model and how surely it sees departures: docs/uncertainty.md
("When the model does not fit"), measured by ``test/test_model_check.py``.
"""

from __future__ import annotations

import math

import numpy as np

from rozyn_estimator.method.likelihood.fitcheck import ALPHA, FITS, NOT_COMPUTABLE, ModelFit, misfit
from rozyn_estimator.method.likelihood.guards import NOISE_AT_ZERO
from rozyn_estimator.method.likelihood.spectra import Spectra, band_power
from rozyn_estimator.method.likelihood.whiteness import whiteness
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective


def full_model_fit(objective: WhittleObjective, theta: np.ndarray, spectra: Spectra, step: int,
                   kappa: float) -> ModelFit:
    """The check at the fit's optimum ``theta``: ``spectra`` the window's (its DFT), ``step`` the
    bins in each of the objective's periodogram means, ``kappa`` the taper's neighbour
    correlation (``neighbour_correlation``)."""
    f = spectra.freq_hz
    if spectra.dft is None:
        raise ValueError("the model-fit check needs the window's DFT (Spectra.dft)")
    not_computable = ModelFit(math.nan, 0.0, math.nan, (float(f[0]), float(f[-1])), NOT_COMPUTABLE)
    try:
        S = objective.factored(theta)[0]
        hess = objective.hess(theta)
    except (ValueError, np.linalg.LinAlgError):  # S singular somewhere: never "fits"
        return not_computable
    model = objective.model
    base = getattr(model, "model", model)  # the spectrum under a corner calibration's shares
    # A floor the fit ran below the model's fixed one is at its boundary: it measures no noise
    # (noise-free sensors), so the check takes it away, and the dither stands for the model's
    # resolution there instead. One far below its channel's power is not free (as the half car's).
    fitted = np.exp(theta[base.noise_slice])
    floors = fitted + base.min_noise_psd
    unknown = np.where(fitted < base.min_noise_psd, floors, 0.0)
    k = S.shape[-1]
    S = S - unknown[:, None] * np.eye(k)
    floors = np.broadcast_to(floors - unknown, S.shape[:2])
    free = np.ones(theta.size, dtype=bool)
    free[base.noise_slice] = fitted > NOISE_AT_ZERO * band_power(spectra)
    A = np.linalg.inv(hess[np.ix_(free, free)])
    group = np.arange(f.size) // step
    ones = np.ones(objective.counts.size)[:, None, None]

    def components(check: np.ndarray | None, at: np.ndarray) -> np.ndarray:
        # W's real and imaginary parts at the groups ``at`` (their inner product tr(W_i W_j)),
        # whitened by the check's S; ∂S mapped to those groups only
        linv = np.linalg.inv(np.linalg.cholesky((S if check is None else check)[at]))
        dS = model.to_targets(objective.evaluated(theta)[1][free], at)
        rows = objective.whitened(linv, dS, ones[: at.size])
        parts = rows.reshape(rows.shape[0], 2, -1, k * k).transpose(0, 2, 1, 3)
        return parts.reshape(rows.shape[0], -1, 2 * k * k)

    d = spectra.dft / math.sqrt(spectra.n_samples * spectra.fs_hz)
    with np.errstate(divide="ignore", invalid="ignore"):
        try:
            tracks = 2 if base.rolls else 1  # the road's inputs
            found = whiteness(S, floors, tracks, d, group, objective.counts, base.freq_hz, kappa, components,
                              A, (hess - np.diag(objective.precision))[np.ix_(free, free)], unknown,
                              spectra.window_dft)
        except np.linalg.LinAlgError:
            return not_computable
    if not math.isfinite(found.statistic):
        return not_computable
    worst = int(np.argmax(found.per_band))
    band = (float(found.edges_hz[worst]), float(min(found.edges_hz[worst + 1], f[-1])))
    p = found.p_value
    verdict = FITS if p >= ALPHA else misfit("full-car" if base.rolls else "half-car", p, band, found,
                                             "the rear sensors" if base.rolls else "the rear sensor")
    return ModelFit(found.statistic, found.dof, p, band, verdict, found.dithered)
