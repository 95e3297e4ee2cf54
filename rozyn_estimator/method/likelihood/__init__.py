"""What the likelihood refinement (:mod:`rozyn_estimator.method.vehicle_fit.refine`, the one for every
car) stands on, ROS-free:

- ``config``: :class:`LikelihoodConfig`, the settings;
- ``spectra``: the window's periodogram matrices (:func:`window_spectra`, :class:`Spectra`);
- ``road_input``: how the road reaches the wheels at a constant or varying speed (the
  wheelbase delay, the tracks' coherence, a drive's mixture of both);
- ``score``: the score's lag covariances and the sandwich's ratio a warm update keeps;
- ``whiteness`` and ``fitcheck``: the model check's statistic and verdicts;
- ``speedcheck``: the speed topic checked against the wheelbase delay the data show;
- ``guards``: a noise floor run aground revived, a step backtracked;
- ``kept``: the last few results of a costly function of a window's arrays (its drive, its
  mixture of delays, the grid's maps), found again by their arguments' values.
"""

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.likelihood.spectra import Spectra, window_spectra

__all__ = ["LikelihoodConfig", "Spectra", "window_spectra"]
