"""Likelihood refinement: a frequency-domain (Whittle) maximum-likelihood fit of the half car.

Rozyn's pipeline (``pipeline.py``) condenses the data into two modes and fits the
inertia to them; this stage fits the whole 4-DOF half car to the whole front/rear
spectral matrix instead, started from Rozyn's estimate.

Modules, by concern (each explains its part):

- ``config``: :class:`LikelihoodConfig`, the settings.
- ``spectra``: the window's periodogram matrices (:func:`window_spectra`, :class:`Spectra`).
- ``road_input``: how one road reaches both axles (:func:`delay_characteristic`).
- ``model``: the half car's spectral matrix and its derivatives (:class:`HalfCarSpectrum`).
- ``objective``: the Whittle likelihood, its gradient and curvatures (:class:`WhittleObjective`).
- ``covariance``: the sandwich covariance and the time blocks' score variance.
- ``fit``: the multi-start fit and its checks (:func:`refine`, :class:`Refinement`).
- ``uncertainty``: what the vehicle's tolerances add to the covariance, by ``augment``
  (calibrating the values the data can inform, ``calibration`` reports them) and
  ``sensitivity`` (propagating the rest).
- ``fitcheck``: whether the spectra fit the model at all (:func:`model_fit`).
"""

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.fit import Refinement, refine
from rozyn_estimator.method.likelihood.model import HalfCarSpectrum
from rozyn_estimator.method.likelihood.objective import WhittleObjective
from rozyn_estimator.method.likelihood.road_input import delay_characteristic
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
