from rozyn_estimator.tools.study._all import *  # noqa: F403
