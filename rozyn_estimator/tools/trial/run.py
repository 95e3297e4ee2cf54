"""Simulated trials: one seeded run of either car through its estimator.

The workhorse of ``rozyn trial``, the study, the method comparison and the benchmark.
As a tool it imports both the plant (``sim_node``) and the estimator; the estimator's
own modules never import the plant (DESIGN.md).
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import Estimate, estimate
from rozyn_estimator.tools.cars import CARS
from rozyn_estimator.tools.trial.spec import TrialSpec
from sim_node.simulation import SimBlock, Simulation


@dataclass(frozen=True)
class TrialResult:
    seed: int
    estimate: Estimate
    truth: np.ndarray  # (k,) in the car's parameter order
    sim_ms: float
    model: str = "half"  # the car: "half" or "full"

    def to_dict(self) -> dict[str, Any]:
        """The JSON record of ``rozyn trial --json`` (the full car's says ``"model": "full"``)."""
        out: dict[str, Any] = {"seed": self.seed}
        if self.model != "half":
            out["model"] = self.model
        out.update(self.estimate.to_dict())
        out["truth"] = dict(zip(CARS[self.model].names, self.truth.tolist(), strict=True))
        return out


def simulate(spec: TrialSpec, seed: int) -> SimBlock:
    """The seeded run's accelerometer samples, with the spec's relative sensor noise added.

    The relative noise (``noise_fraction``) is white, with a standard deviation of that
    share of each channel's rms as simulated (about its mean: gravity and bias do not
    count), from its own random stream (the car's ``noise_stream``).
    """
    block = Simulation(spec.sim_config(seed)).run(spec.duration_s)
    if spec.noise_fraction > 0:
        accel = block.accel_mps2
        rms = accel.std(axis=0)
        noise = np.random.default_rng([seed, spec.car.noise_stream]).standard_normal(accel.shape)
        block = dataclasses.replace(block, accel_mps2=accel + noise * (spec.noise_fraction * rms))
    return block


def run_trial(spec: TrialSpec, seed: int) -> TrialResult:
    """Simulate one seeded run and estimate from it."""
    started = time.perf_counter()
    block = simulate(spec, seed)
    sim_ms = (time.perf_counter() - started) * 1e3
    est = estimate_block(spec, block)
    return TrialResult(seed=seed, estimate=est, truth=spec.truth, sim_ms=sim_ms, model=spec.car.name)


def estimate_block(spec: TrialSpec, block: SimBlock, method: str | None = None, warm: Any = None,
                   n: int | None = None) -> Estimate:
    """Run the car's estimator of ``method`` (default: the spec's) on a simulated block (its
    first ``n`` samples; default: all), warm-started from ``warm`` if given.

    The estimator is told the speed per sample (as from a speed topic; times ``1 +
    speed_error``) and the spec's estimator vehicle (which may carry value errors).
    """
    accel, speed = block.accel_mps2, block.speed_mps * (1.0 + spec.speed_error)
    if n is not None:
        accel, speed = accel[:n], speed[:n] if np.ndim(speed) else speed
    return estimate(accel, spec.rate_hz, spec.estimator_vehicle, spec.pipeline_config(method), speed, warm,
                    tuple(block.channels))


def _run_trial_args(args: tuple[TrialSpec, int]) -> TrialResult:
    return run_trial(*args)


def limit_threads() -> None:
    """One BLAS thread per process: the matrices are tiny and processes run in parallel."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)


def default_jobs() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_trials(
    spec: TrialSpec, seeds: Sequence[int], jobs: int | None = None, progress: bool = False
) -> Iterator[TrialResult]:
    """Trials for each seed, in seed order, on ``jobs`` processes (default: all cores)."""
    yield from parallel_map(_run_trial_args, [(spec, int(s)) for s in seeds], jobs, progress, "trial")


def parallel_map(
    fn: Callable[[Any], Any], work: Sequence[Any], jobs: int | None = None, progress: bool = False,
    unit: str = "item",
) -> Iterator[Any]:
    """``fn`` over ``work`` in order on ``jobs`` processes (default: all cores), one BLAS
    thread each, with a progress bar on stderr if asked. ``fn`` must be picklable."""
    from tqdm import tqdm

    jobs = default_jobs() if jobs is None else max(1, int(jobs))
    with tqdm(total=len(work), unit=unit, disable=not progress, leave=False, dynamic_ncols=True) as bar:
        if jobs == 1 or len(work) <= 1:
            limit_threads()
            for item in work:
                yield fn(item)
                bar.update(1)
            return
        chunk = max(1, min(16, len(work) // (4 * jobs)))
        with ProcessPoolExecutor(max_workers=jobs, initializer=limit_threads) as pool:
            for result in pool.map(fn, work, chunksize=chunk):
                yield result
                bar.update(1)


def parse_seeds(text: str) -> list[int]:
    """``"7"``, ``"1-100"``, ``"1,5,9-12"`` -> list of seeds (>= 0)."""
    seeds: list[int] = []
    try:
        for part in text.split(","):
            lo, _, hi = part.strip().partition("-")
            first, last = int(lo), int(hi) if hi else int(lo)
            if first < 0 or last < first:
                raise ValueError
            seeds.extend(range(first, last + 1))
    except ValueError:
        raise ConfigError(f"seeds: expected N, A-B or a comma list of those (N >= 0), got {text!r}") from None
    return seeds
