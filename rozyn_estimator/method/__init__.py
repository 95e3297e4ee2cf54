"""The method, ROS-free (numpy and scipy only): Rozyn's pipeline and the likelihood refinement.

``estimate`` runs one update on a window of paired front/rear accelerations; see
:mod:`rozyn_estimator.method.pipeline`.
"""

from rozyn_estimator.method.config import METHODS, PARAM_NAMES, PipelineConfig
from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.method.pipeline import Estimate, estimate

__all__ = ["METHODS", "PARAM_NAMES", "Estimate", "LikelihoodConfig", "PipelineConfig", "estimate"]
