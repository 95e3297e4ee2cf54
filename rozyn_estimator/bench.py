"""``rozyn bench``: speed figures of the core, as JSON.

Each figure is the median over ``repeats`` runs after one warm-up, single BLAS thread
(as the trials run). Peak memory is the process' maximum resident set size.
"""

from __future__ import annotations

import resource
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

from rozyn_estimator.pipeline import PipelineConfig, estimate
from rozyn_estimator.trial import TrialSpec, limit_threads
from rozyn_estimator.vehicle import Vehicle
from sim_node.road import Road, RoadSpec
from sim_node.simulation import SimConfig, Simulation


def _median_ms(fn: Callable[[], Any], repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def _peak_rss_mb() -> float:
    scale = 1024.0 if sys.platform != "darwin" else 1024.0 * 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / scale


def run_bench(repeats: int = 20) -> dict[str, Any]:
    """Figures of issue 2's goals (sim 100 s at 100 Hz <= 20 ms; update <= 10 ms)."""
    limit_threads()
    vehicle = Vehicle()
    sim_cfg = SimConfig(duration_s=100.0)
    window = Simulation(SimConfig(duration_s=120.0)).run(120.0)
    accel = window.accel_mps2
    speed = sim_cfg.speed_mps
    out: dict[str, Any] = {
        "sim_100s_at_100hz_ms": _median_ms(lambda: Simulation(sim_cfg).run(100.0), repeats),
        "road_generation_ms": _median_ms(lambda: Road(RoadSpec(), 1, period_m=2800.0), repeats),
        "update_120s_window_ms": _median_ms(
            lambda: estimate(accel, 100.0, vehicle, PipelineConfig(), speed), repeats),
        "update_120s_window_no_variance_ms": _median_ms(
            lambda: estimate(accel, 100.0, vehicle, PipelineConfig(variance="none"), speed), repeats),
        "trial_100s_iso_ms": _median_ms(lambda: _trial(), max(3, repeats // 4)),
        "study_trials_per_second": _study_trials_per_second(max(1, repeats // 10)),
    }
    out["peak_rss_mb"] = _peak_rss_mb()
    out["goals"] = {"sim_100s_at_100hz_ms": 20.0, "update_120s_window_ms": 10.0}
    return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in out.items()}


def _trial() -> None:
    from rozyn_estimator.trial import run_trial

    run_trial(TrialSpec(), 1)


def _study_trials_per_second(repeats: int) -> float:
    """One core over the thesis grid's mix of measurement times (``rozyn study``)."""
    from rozyn_estimator.study import bench_trials_per_second

    return bench_trials_per_second(repeats)
