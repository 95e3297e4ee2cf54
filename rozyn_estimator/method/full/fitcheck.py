"""Does the full-car model describe the data? The goodness-of-fit check of each refined update.

The half car's check (:mod:`rozyn_estimator.method.likelihood.fitcheck`) widened to k
channels: in each of ``N_BANDS`` log-spaced bands the mean ``M_b`` of the whitened
periodogram matrices ``L⁻¹ I Lᴴ⁻¹`` (``S = L Lᴴ`` the fitted model's) should be the k×k
identity; the complex-Wishart likelihood-ratio statistic

    T = Σ_b 2 n_b (tr M_b - ln det M_b - k)

is χ² with ``k² B`` degrees of freedom less the fit's parameters, ``n_b`` the band's
ordinates over the taper's neighbour correlation ``κ`` (the fit's means over neighbouring
bins count as the bins they hold). Misfit means power or coherence between the corners the
model cannot produce: suspension or tyre values off the vehicle file's (the full car holds
them fixed: its budget carries their tolerances at first order), a nonlinear suspension
(its forces at combination frequencies), a sensor's gain or timing beyond what its
tolerance lets the calibration absorb, a body that is not rigid between the sensors.

Not on noise-free data (the simulator's exact sensors, no real accelerometer's): four
sensors on a rigid body then span three motions, S is singular in the fourth direction and
the check has no distribution (the refinement carries none).

Measured here (Table 5-1's full car, ISO A, 100 km/h, 120 s, 20 seeds): at 10 % sensor
noise T = 115 ± 10 at 112 degrees of freedom in the model (p < 0.001 in none; 0.1 % and 1 %
noise: 8 seeds each, none), 442 ± 43 with dampers twice as stiff in rebound (in every one).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

from rozyn_estimator.method.full.whittle import FullWhittle
from rozyn_estimator.method.likelihood.fitcheck import ALPHA, FITS, N_BANDS, NOT_COMPUTABLE, ModelFit


def full_model_fit(objective: FullWhittle, theta: np.ndarray, freq_hz: np.ndarray, kappa: float) -> ModelFit:
    """The check at the fit's optimum ``theta``; ``freq_hz`` the objective's periodograms'
    frequencies, ``kappa`` the taper's neighbour correlation (``neighbour_correlation``)."""
    f = np.asarray(freq_hz, dtype=float)
    W = objective.whitened_periodogram(theta)
    k = objective.periodogram.shape[-1]
    dof = max(1, k * k * N_BANDS - objective.model.n_params)
    if W is None or not np.all(np.isfinite(W)):  # S singular somewhere: never "fits"
        return ModelFit(math.nan, dof, math.nan, (float(f[0]), float(f[-1])), NOT_COMPUTABLE)
    edges = np.geomspace(f[0], f[-1] * (1 + 1e-9), N_BANDS + 1)
    starts = np.searchsorted(f, edges[:-1])  # f ascending: each band's ordinates are a run
    counts = np.add.reduceat(objective.counts, starts)
    M = np.add.reduceat(objective.counts[:, None, None] * W, starts, axis=0) / counts[:, None, None]
    sign, log_det = np.linalg.slogdet(M)
    trace = np.einsum("baa->b", M).real
    per_band = 2.0 * counts / kappa * np.where(sign.real > 0, trace - log_det.real - k, np.inf)
    statistic = float(np.sum(per_band))
    if not math.isfinite(statistic):
        return ModelFit(math.nan, dof, math.nan, (float(f[0]), float(f[-1])), NOT_COMPUTABLE)
    p = float(special.chdtrc(dof, statistic))
    worst = int(np.argmax(per_band))
    band = (float(edges[worst]), float(min(edges[worst + 1], f[-1])))
    verdict = FITS if p >= ALPHA else (
        f"the full-car model does not fit the spectra (p = {p:.1g}; worst {band[0]:.2g}-{band[1]:.2g} Hz): "
        "likely suspension or tyre values off the vehicle file's, a nonlinear suspension (dampers stiffer "
        "in rebound, progressive springs), a sensor's gain or timing beyond its tolerance, or a body that is "
        "not rigid between the sensors")
    return ModelFit(statistic, dof, p, band, verdict)
