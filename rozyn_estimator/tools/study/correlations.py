"""The data of the correlation figures: a cell's normalised autocorrelations, recomputed.

The study does not store the records; the same seeds give the same records as the
study's trials, so :func:`cell_correlations` simulates them again (the thesis' Figs 5-3,
5-4, 5-14, 5-15): the half car's front and rear accelerometers, or the full car's four
corners.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.tools.study.settings import Cell, StudySettings
from rozyn_estimator.tools.study.work import one_blas_thread
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle


@dataclass(frozen=True)
class CellCorrelations:
    """Normalised autocorrelations of a cell's trials (the thesis' Figs 5-3, 5-4, 5-14, 5-15)."""

    cell: Cell
    lag_s: np.ndarray  # (n_lags,)
    acf: np.ndarray  # (n_trials, n_lags, k): R_ii(tau) / R_ii(0), per accelerometer (the model's channels)
    fit_lags_s: tuple[float, float]  # the lags the pipeline identifies from [s]


def cell_correlations(
    settings: StudySettings, cell: Cell, trials: Sequence[int] | None = None, max_lag_s: float = 3.0
) -> CellCorrelations:
    """Recompute a cell's autocorrelations from the simulation (they are not stored per trial).

    The same seeds give the same records as the study's trials (default: its first 100).
    """
    from rozyn_estimator.method.correlation import correlation_sums
    from rozyn_estimator.tools.trial.run import simulate

    one_blas_thread()
    trials = range(min(100, settings.trials)) if trials is None else trials
    spec = settings.trial_spec(cell)
    max_lag = round(max_lag_s * settings.rate_hz)
    acf = np.empty((len(trials), max_lag + 1, len(settings.car.channels)))
    for i, trial in enumerate(trials):
        seed = settings.seed(cell, trial)
        y = simulate(spec, seed).accel_mps2  # the trial's record, its relative noise included
        sums = correlation_sums(y - y.mean(axis=0), max_lag)[0]
        acf[i] = np.column_stack([sums[:, j, j] / sums[0, j, j] for j in range(acf.shape[2])])
    return CellCorrelations(cell, np.arange(max_lag + 1) / settings.rate_hz, acf,
                            fit_lag_window_s(settings.pipeline_config(), settings.studied_vehicle,
                                             cell.speed_kmh))


def focus_correlations(
    settings: StudySettings, cells: Sequence[Cell], pmap: Callable[..., Iterable[Any]] = map, parts: int = 1
) -> list[CellCorrelations]:
    """:func:`cell_correlations` of several cells, each cut into ``parts`` tasks for ``pmap``."""
    trials = np.array_split(np.arange(min(100, settings.trials)), parts)
    tasks = [(settings, cell, tuple(int(t) for t in part)) for cell in cells for part in trials if len(part)]
    pieces = list(pmap(_correlation_task, tasks))
    out = []
    for cell in cells:
        mine = [p for p in pieces if p.cell == cell]
        out.append(dataclasses.replace(mine[0], acf=np.concatenate([p.acf for p in mine])))
    return out


def _correlation_task(task: tuple[StudySettings, Cell, tuple[int, ...]]) -> CellCorrelations:
    return cell_correlations(*task)


def fit_lag_window_s(
    cfg: PipelineConfig, vehicle: Vehicle | FullVehicle, speed_kmh: float
) -> tuple[float, float]:
    """First and last correlation lag the pipeline uses at a speed [s] (pipeline step 1)."""
    first = cfg.min_lag_s
    if cfg.skip_wheelbase_delay:
        first = max(first, vehicle.wheelbase_m / (speed_kmh / 3.6))
    return first, first + cfg.max_lag_s
