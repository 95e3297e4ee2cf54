from rozyn_estimator.method.likelihood._all import *  # noqa: F403
from rozyn_estimator.method.likelihood._all import _band_power, _inv2, _refine, _score_series  # noqa: F401
