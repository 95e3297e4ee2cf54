"""Settings of one update (the ``pipeline.*`` parameters) and the named methods."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

from rozyn_estimator.method.fit import FIT_KINDS, STIFFNESS_MODELS
from rozyn_estimator.method.identification import IDENTIFIERS
from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.parameters import check, param

PARAM_NAMES = ("mass_kg", "pitch_inertia_kgm2", "cog_from_front_axle_m")
FULL_PARAM_NAMES = ("mass_kg", "roll_inertia_kgm2", "pitch_inertia_kgm2", "cog_from_front_axle_m",
                    "cog_lateral_m")
"""The full car's estimated parameters, in the order of its estimates and covariance."""
CORRELATIONS = ("multi-reference", "thesis-acf", "free-decay")
VARIANCES = ("jackknife", "none")
REFINES = ("likelihood", "none")


@dataclass(frozen=True)
class PipelineConfig:
    """Settings of one update. Times in s, frequencies in Hz."""

    PARAM_PREFIX: ClassVar[str] = "pipeline."

    identifier: str = param("state-transition", "modal identification method", choices=tuple(IDENTIFIERS))
    # eq 2-5: p = gamma 2n/m; correlation estimates are noisy (thesis: 4-6)
    gamma: int = param(4, "eq 2-5 factor: pseudo-measurement blocks p = gamma 2n/m", low=1)
    n_dof: int = param(4, "degrees of freedom n of eq 2-4", low=2)
    correlation: str = param("multi-reference", "free-decay source: multi-reference, thesis-acf or "
                             "free-decay", choices=CORRELATIONS)
    max_lag_s: float = param(1.0, "length of the correlation function used as free decay", unit="s",
                             low=0.0, open_low=True)
    min_lag_s: float = param(0.0, "first correlation lag used", unit="s", low=0.0)
    skip_wheelbase_delay: bool = param(True, "skip lags shorter than wheelbase/speed when the speed is known")
    freq_band_hz: tuple[float, float] = param((0.5, 4.0), "[min, max] natural frequency of the body modes",
                                              unit="Hz", low=0.0, open_low=True, length=2)
    damping_band: tuple[float, float] = param((0.02, 0.9), "[min, max] damping ratio of the body modes",
                                              low=0.0, high=1.0, length=2)
    stiffness_model: str = param("eq2-22", "corner stiffness: eq2-21, eq2-22 or condensed",
                                 choices=STIFFNESS_MODELS)
    fit: str = param("modal", "fit of A0: modal or stiffness-block", choices=FIT_KINDS)
    variance: str = param("jackknife", "covariance method: jackknife or none", choices=VARIANCES)
    jackknife_blocks: int = param(10, "blocks of the jackknife", low=4)
    min_duration_s: float = param(5.0, "shortest window the pipeline accepts", unit="s",
                                  low=0.0, open_low=True)
    refine: str = param("likelihood", "after Rozyn's pipeline: likelihood (the Whittle fit of the half car) "
                        "or none", choices=REFINES)
    likelihood: LikelihoodConfig = param(description="the refinement's settings",
                                         default_factory=LikelihoodConfig)

    def __post_init__(self) -> None:
        check(self, (
            ("freq_band_hz", lambda c: c.freq_band_hz[0] < c.freq_band_hz[1], "needs 0 < min < max"),
            ("damping_band", lambda c: c.damping_band[0] < c.damping_band[1], "needs 0 <= min < max <= 1"),
            ("refine", lambda c: not (c.refine == "likelihood" and c.correlation == "free-decay"),
             "the likelihood refinement models a road-driven response; use refine='none' with "
             "correlation='free-decay'"),
        ))

    @property
    def p_blocks(self) -> int:
        """p = gamma * 2n / m (eq 2-5) with m = 2 sensors."""
        return math.ceil(self.gamma * 2 * self.n_dof / 2)

    def replace(self, **changes: Any) -> PipelineConfig:
        return dataclasses.replace(self, **changes)


# Named methods (``rozyn trial --method``, ``rozyn compare --methods``). ``PipelineConfig()``
# (the pipeline's default) is ``likelihood``; the ``rozyn*`` and ``thesis`` methods are
# Rozyn's pipeline alone.
METHODS: dict[str, PipelineConfig] = {
    "rozyn": PipelineConfig(refine="none"),
    "rozyn-eq2-21": PipelineConfig(stiffness_model="eq2-21", refine="none"),
    "rozyn-condensed": PipelineConfig(stiffness_model="condensed", refine="none"),
    # The thesis' choices, with its equations implemented correctly.
    "thesis": PipelineConfig(
        gamma=2, correlation="thesis-acf", stiffness_model="eq2-21", fit="stiffness-block",
        freq_band_hz=(1.0, 3.0), damping_band=(0.1, 0.5), skip_wheelbase_delay=False, refine="none",
    ),
    # Rozyn's pipeline, then the Whittle fit of the whole vehicle (method/vehicle_fit/refine.py).
    "likelihood": PipelineConfig(),
}
