"""Statistics of a set of trials of one car (:func:`summarise`), per parameter in the car's order."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from rozyn_estimator.tools.trial.run import TrialResult


@dataclass(frozen=True)
class Summary:
    """Statistics of a set of trials, per parameter in the car's order (k of them)."""

    n: int
    failures: int
    truth: np.ndarray
    mean: np.ndarray
    std: np.ndarray  # the spread of the estimates over the trials
    bias_pct: np.ndarray  # of the truth (NaN where the truth is 0)
    within_6pct: np.ndarray  # share of successful trials within 6 % of truth
    mean_reported_std: np.ndarray  # rms of the published std; NaN when no covariance was reported
    median_ms: float
    coverage_95: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # truth within ±1.96 std
    rms_error: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # √mean (estimate - truth)²
    model_warn_share: float = float("nan")  # refined estimates whose model-fit check warned

    @property
    def bias(self) -> np.ndarray:
        """The mean's error, in the parameters' units."""
        return self.mean - self.truth


def summarise(results: Iterable[TrialResult]) -> Summary:
    results = list(results)
    ok = [r for r in results if r.estimate.ok]
    truth = results[0].truth if results else np.full(3, np.nan)
    k = len(truth)
    if not ok:
        nan = np.full(k, np.nan)
        return Summary(len(results), len(results), truth, nan, nan, nan, nan, nan, float("nan"),
                       nan, nan)
    p = np.array([r.estimate.params for r in ok])
    stds = np.array([r.estimate.std if r.estimate.std is not None else np.full(k, np.nan) for r in ok])
    with np.errstate(divide="ignore", invalid="ignore"):  # a truth of 0 (the lateral CoG)
        relative = p / truth - 1.0
        bias_pct = (p.mean(axis=0) / truth - 1.0) * 100.0
    return Summary(
        n=len(results),
        failures=len(results) - len(ok),
        truth=truth,
        mean=p.mean(axis=0),
        std=p.std(axis=0, ddof=1) if len(ok) > 1 else np.zeros(k),
        bias_pct=np.where(truth == 0, np.nan, bias_pct),
        within_6pct=np.mean(np.abs(relative) <= 0.06, axis=0),
        mean_reported_std=np.sqrt(np.mean(stds**2, axis=0)),
        median_ms=float(np.median([r.estimate.elapsed_ms for r in ok])),
        coverage_95=np.mean(np.abs(p - truth) <= 1.96 * stds, axis=0) if np.all(np.isfinite(stds)) else
        np.full(k, np.nan),
        rms_error=np.sqrt(np.mean((p - truth) ** 2, axis=0)),
        model_warn_share=_model_warn_share(ok),
    )


def _model_warn_share(ok: list[TrialResult]) -> float:
    fits = [r.estimate.refinement.model_fit for r in ok
            if r.estimate.refinement is not None and r.estimate.refinement.model_fit is not None]
    return float(np.mean([not f.ok for f in fits])) if fits else float("nan")
