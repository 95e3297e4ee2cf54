"""The periodogram's means over neighbouring bins (:func:`grouped`), what each mean expects
of S (:func:`kernel_m2`), and a cold start's first fit on coarser means (:func:`coarse_fit`),
for the full car's refinement (:mod:`.refine`)."""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.spectra import Spectra, taper_window
from rozyn_estimator.method.vehicle_fit.grid import expected_periodogram_m2
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.whittle import WhittleObjective, scoring

GROUP_HZ = 0.02  # the fit's periodogram means span at most this (:mod:`.refine`'s docstring)
_COARSE_HZ = 0.1  # a cold start's first fit: means over this (:func:`coarse_fit`)
_COARSE_TOL = 5.0  # ... to this Newton decrement


def grouped(freq_hz: np.ndarray, periodogram: np.ndarray, step: int) -> tuple[np.ndarray, ...]:
    """(frequencies, periodogram matrices, counts) of the means over ``step`` neighbouring bins:
    the model is smooth on that scale (``grid_hz``), and the means' Wishart likelihood keeps
    nearly all the information at a ``step``-th of the work."""
    if step <= 1:
        return freq_hz, periodogram, np.ones(freq_hz.size)
    starts = np.arange(0, freq_hz.size, step)
    counts = np.diff(np.r_[starts, freq_hz.size]).astype(float)
    return (np.add.reduceat(freq_hz, starts) / counts,
            np.add.reduceat(periodogram, starts, axis=0) / counts[:, None, None], counts)


def coarse_fit(spectra: Spectra, n: int, model: VehicleSpectrum,
               cfg: LikelihoodConfig) -> Callable[[np.ndarray], np.ndarray]:
    """θ → a cold start's fit on coarser means (``_COARSE_HZ``), to ``_COARSE_TOL``: far
    from the optimum a Newton step needs only the likelihood's broad shape, at a fraction of
    the work; the fine fit then takes a step or two. θ itself where that fit fails. The coarse
    model is built at the first call: a warm update, which starts at the last optimum, makes none
    (building it cost 2-3 ms of every update)."""
    step = max(1, int(_COARSE_HZ * n / spectra.fs_hz + 1e-9))
    if model.grid_hz <= 0 or spectra.freq_hz.size // step < 50:
        return lambda theta: theta

    @functools.cache
    def objective() -> WhittleObjective:
        freq, periodogram, counts = grouped(spectra.freq_hz, spectra.periodogram, step)
        coarse = model.regrid(freq, kernel_m2(n, spectra.fs_hz, cfg.taper, counts), 2.0 * model.grid_hz)
        return WhittleObjective(coarse, periodogram, counts)

    def fit(theta: np.ndarray) -> np.ndarray:
        res = scoring(objective(), theta, _COARSE_TOL, cfg.max_iter)
        return res.x if np.isfinite(res.fun) else theta

    return fit


def kernel_m2(n: int, fs: float, taper: float, counts: np.ndarray) -> np.ndarray:
    """Each mean ordinate's averaging kernel's second moment [Hz²]: the taper's spectral window
    and the spread of the group's bins, ``Δf² (c² - 1) / 12`` (:func:`expected_periodogram_m2`;
    an untapered window is taken as periodic, as the simulator's records are: no smoothing)."""
    window_m2 = expected_periodogram_m2(taper_window(n, taper), fs) if taper > 0 else 0.0
    return window_m2 + (fs / n) ** 2 * (counts**2 - 1.0) / 12.0
