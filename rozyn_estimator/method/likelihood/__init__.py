"""Likelihood refinement: a frequency-domain (Whittle) maximum-likelihood fit of the half car.

Rozyn's pipeline (``pipeline.py``) condenses the data into two modes and fits the
inertia to them; this stage fits the whole 4-DOF half car to the whole front/rear
spectral matrix instead, started from Rozyn's estimate.

Modules, by concern (each explains its part):

- ``config``: :class:`LikelihoodConfig`, the settings.
- ``spectra``: the window's periodogram matrices (:func:`window_spectra`, :class:`Spectra`).
- ``model``: the half car's spectral matrix and its derivatives (:class:`HalfCarSpectrum`,
  :func:`delay_characteristic`).
- ``objective``: the Whittle likelihood, its gradient and curvatures (:class:`WhittleObjective`).
- ``covariance``: the sandwich covariance and the time blocks' score variance.
- ``fit``: the multi-start fit and its checks (:func:`refine`, :class:`Refinement`).
"""

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.fit import Refinement, refine
from rozyn_estimator.method.likelihood.model import HalfCarSpectrum, delay_characteristic
from rozyn_estimator.method.likelihood.objective import WhittleObjective
from rozyn_estimator.method.likelihood.spectra import Spectra, window_spectra

__all__ = [
    "HalfCarSpectrum",
    "LikelihoodConfig",
    "Refinement",
    "Spectra",
    "WhittleObjective",
    "delay_characteristic",
    "refine",
    "window_spectra",
]
