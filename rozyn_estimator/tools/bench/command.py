"""``rozyn bench``: speed figures of the core, as JSON (the command and its figures).

Each figure is the median over ``repeats`` runs after one warm-up, single BLAS thread
(as the trials run). Peak memory is the process' maximum resident set size. With
``--nodes``, the estimator node under load over DDS instead
(:mod:`rozyn_estimator.tools.bench.nodes`); with ``--silent-sensor``, the online
estimator's resident memory over an hour of a 1 kHz front sensor whose rear partner
never speaks (it must stay flat: each channel holds at most two windows).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import resource
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rozyn_estimator.method import METHODS, PipelineConfig, estimate
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.tools.options import with_sensor_preset
from rozyn_estimator.tools.trial.run import limit_threads
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle
from sim_node.road import Road, RoadSpec
from sim_node.sensors import MEMS_GYRO_NOISE_RADPS, MEMS_NOISE_MPS2
from sim_node.simulation import SimConfig, Simulation

HELP = "time the simulator and the pipeline (JSON)"
DESCRIPTION = None  # ``rozyn bench --help``: the usage and the options only


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--repeats", type=int, default=20, help="timing repeats (default: 20)")
    p.add_argument("--nodes", action="store_true",
                   help="instead: the estimator node under load over DDS (about 11 minutes)")
    p.add_argument("--quick", action="store_true", help="with --nodes: shorter runs (about 5 minutes)")
    p.add_argument("--silent-sensor", action="store_true",
                   help="instead: memory over an hour of 1 kHz front samples, the rear silent (seconds)")


def run(args: argparse.Namespace) -> int:
    """``rozyn bench``: the figures as JSON on stdout."""
    if args.nodes:
        from rozyn_estimator.tools.bench.nodes import run_node_bench

        print(json.dumps(run_node_bench(quick=args.quick), indent=2))
        return 0
    if args.silent_sensor:
        print(json.dumps([run_silent_sensor_bench(), run_silent_sensor_bench(one_by_one=True)], indent=2))
        return 0
    print(json.dumps(run_bench(repeats=args.repeats), indent=2))
    return 0


def _median_ms(fn: Callable[[], Any], repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def _paired_ms(fns: Sequence[Callable[[], Any]], repeats: int) -> list[float]:
    """Median times [ms] of ``fns`` run in turn within each repeat: a ratio of two of them
    then compares runs made moments apart (this machine's speed drifts within a run: two
    medians taken a minute apart gave a ratio between 2.5 and 3.5 for the same code)."""
    for fn in fns:
        fn()
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(repeats):
        for fn, out in zip(fns, times, strict=True):
            t0 = time.perf_counter()
            fn()
            out.append((time.perf_counter() - t0) * 1e3)
    return [statistics.median(t) for t in times]


def _full_car_figures(repeats: int, half_warm: Callable[[], Any],
                      half_cold: Callable[[], Any]) -> dict[str, float]:
    """The full car's refined update (120 s, 100 Hz, four sensors, the default tolerances'
    budget) cold and warm, and per the half car's (``half_warm``, ``half_cold``: its updates)
    timed in turn with it (goal: <= 3x)."""
    vehicle = FullVehicle()
    live = Simulation(SimConfig(model="full", full_vehicle=vehicle, road=RoadSpec(amplitudes="gaussian"),
                                seed=3, noise_std_mps2=0.05))
    window = live.run(120.0).accel_mps2
    nxt = np.vstack([window[500:], live.run(5.0).accel_mps2])
    speed = live.config.speed_mps
    warm = estimate(window, 100.0, vehicle, PipelineConfig(), speed)

    def full_cold() -> Any:
        return estimate(window, 100.0, vehicle, PipelineConfig(), speed)

    def full_warm() -> Any:
        return estimate(nxt, 100.0, vehicle, PipelineConfig(), speed, warm_start=warm)

    cold_ms, half_cold_ms = _paired_ms([full_cold, half_cold], max(5, repeats // 2))
    warm_ms, half_warm_ms = _paired_ms([full_warm, half_warm], repeats)
    return {"full_refined_update_cold_ms": cold_ms, "full_refined_update_warm_ms": warm_ms,
            "full_refined_warm_per_half": warm_ms / half_warm_ms,
            "full_refined_cold_per_half": cold_ms / half_cold_ms}


URBAN_UPDATES = 12  # the warm updates of a minute of the urban drive, 5 s apart


def _urban_figures(repeats: int, half_warm: Callable[[], Any],
                   half_cold: Callable[[], Any]) -> dict[str, float]:
    """The half car's refined update on 120 s urban windows (the ``udds`` cycle from 400 s: a
    stop, pulling away and braking; Gaussian ISO A, MEMS noise, the default tolerances), per the
    constant-speed update timed in turn with it (goal: <= 1.5x). Cold: the window from 400 s.
    Warm: the minute's :data:`URBAN_UPDATES` updates after it, each from the one before as the
    node runs them, their mean: one window's time depends on how far its noise floors move
    from the last one's (on one drive 0.8-3.1x the constant-speed update's), so no one window
    stands for a drive. The slowest of them is reported too."""
    vehicle = Vehicle()
    live = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=3,
                                noise_std_mps2=MEMS_NOISE_MPS2, drive_cycle_file="udds"))
    live.run(400.0)
    block = live.run(120.0 + 5.0 * URBAN_UPDATES)
    n, step = 120 * 100, 5 * 100  # samples at 100 Hz
    windows = [(block.accel_mps2[i: i + n], block.speed_mps[i: i + n])
               for i in range(0, step * URBAN_UPDATES + 1, step)]
    window, speed = windows[0]
    previous = estimate(window, 100.0, vehicle, PipelineConfig(), speed)
    updates: list[Callable[[], Any]] = []
    for acc, spd in windows[1:]:
        updates.append(functools.partial(estimate, acc, 100.0, vehicle, PipelineConfig(), spd,
                                         warm_start=previous))
        result = updates[-1]()
        previous = result if result.params is not None else previous

    def urban_cold() -> Any:
        return estimate(window, 100.0, vehicle, PipelineConfig(), speed)

    cold_ms, constant_cold_ms = _paired_ms([urban_cold, half_cold], max(5, repeats // 2))
    *warm_each_ms, constant_warm_ms = _paired_ms([*updates, half_warm], max(3, repeats // 2))
    warm_ms = statistics.fmean(warm_each_ms)
    return {"urban_update_cold_ms": cold_ms, "urban_update_warm_ms": warm_ms,
            "urban_update_warm_slowest_ms": max(warm_each_ms),
            "urban_cold_per_constant": cold_ms / constant_cold_ms,
            "urban_warm_per_constant": warm_ms / constant_warm_ms}


def _imu_figures(repeats: int) -> dict[str, float]:
    """One IMU's warm refined update (``--sensors imu``'s: the half car's accel_z and gyro_y, the
    full car's with gyro_x), and per the accelerometers' (two at the axles, four at the corners)
    timed in turn with it (Gaussian ISO A, 100 km/h, MEMS noise, the default tolerances)."""
    out: dict[str, float] = {}
    for prefix, base in (("", Vehicle()), ("full_", FullVehicle())):
        imu_ms, accel_ms = _paired_ms([_warm_update(with_sensor_preset(base, "imu")), _warm_update(base)],
                                      max(3, repeats // 2))
        out[f"{prefix}imu_update_warm_ms"] = imu_ms
        out[f"{prefix}imu_warm_per_accelerometers"] = imu_ms / accel_ms
    return out


def _warm_update(vehicle: Vehicle | FullVehicle) -> Callable[[], Any]:
    """The next window's refined update (5 s later, from this one's) of ``vehicle``'s sensors."""
    car: dict[str, Any] = {"model": "full", "full_vehicle": vehicle} if isinstance(vehicle, FullVehicle) \
        else {"vehicle": vehicle}
    live = Simulation(SimConfig(**car, road=RoadSpec(amplitudes="gaussian"), seed=3,
                                noise_std_mps2=MEMS_NOISE_MPS2, gyro_noise_std_radps=MEMS_GYRO_NOISE_RADPS))
    window = live.run(120.0).accel_mps2
    nxt = np.vstack([window[500:], live.run(5.0).accel_mps2])
    speed = live.config.speed_mps
    warm = estimate(window, 100.0, vehicle, PipelineConfig(), speed)
    return lambda: estimate(nxt, 100.0, vehicle, PipelineConfig(), speed, warm_start=warm)


def _peak_rss_mb() -> float:
    scale = 1024.0 if sys.platform != "darwin" else 1024.0 * 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / scale


def run_bench(repeats: int = 20) -> dict[str, Any]:
    """Figures against the goals: sim 100 s at 100 Hz <= 20 ms; Rozyn's update (120 s
    window, with its covariance) <= 10 ms; refined update warm <= 20 ms and cold <= 60 ms,
    or in the same run warm <= 2.5x and cold <= 7x Rozyn's update with its covariance; the
    uncertainty budget (default tolerances against none) adds <= 30 % to a warm refined
    update; a window holding a glitch (one 1e6 m/s² sample) costs <= 2x a clean one; the
    full car's refined update (four sensors) <= 3x the half car's, cold and warm."""
    limit_threads()
    vehicle = Vehicle()
    exact = dataclasses.replace(vehicle, tolerances=Tolerances.none())
    sim_cfg = SimConfig(duration_s=100.0)
    # a window from an endless Gaussian road with 10 % noise: what a vehicle gives
    live = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=3, noise_std_mps2=0.05))
    window = live.run(120.0).accel_mps2
    rozyn = METHODS["rozyn"]
    speed = sim_cfg.speed_mps
    warm = estimate(window, 100.0, vehicle, PipelineConfig(), speed)
    nxt = np.vstack([window[500:], live.run(5.0).accel_mps2])  # the next window, 5 s later
    glitched = nxt.copy()
    glitched[len(nxt) // 2, 0] = 1e6
    warm_exact = estimate(window, 100.0, exact, PipelineConfig(), speed)
    out: dict[str, Any] = {
        "sim_100s_at_100hz_ms": _median_ms(lambda: Simulation(sim_cfg).run(100.0), repeats),
        "road_generation_ms": _median_ms(lambda: Road(RoadSpec(), 1, period_m=2800.0), repeats),
        "update_120s_window_ms": _median_ms(lambda: estimate(window, 100.0, vehicle, rozyn, speed), repeats),
        "update_120s_window_no_variance_ms": _median_ms(
            lambda: estimate(window, 100.0, vehicle, rozyn.replace(variance="none"), speed), repeats),
        "refined_update_cold_ms": _median_ms(
            lambda: estimate(window, 100.0, vehicle, PipelineConfig(), speed), max(3, repeats // 4)),
        "refined_update_warm_ms": _median_ms(
            lambda: estimate(nxt, 100.0, vehicle, PipelineConfig(), speed, warm_start=warm),
            max(3, repeats // 2)),
        "refined_update_warm_without_budget_ms": _median_ms(
            lambda: estimate(nxt, 100.0, exact, PipelineConfig(), speed, warm_start=warm_exact),
            max(3, repeats // 2)),
        "glitch_update_warm_ms": _median_ms(
            lambda: estimate(glitched, 100.0, vehicle, PipelineConfig(), speed, warm_start=warm),
            max(3, repeats // 2)),
        "trial_100s_iso_ms": _median_ms(lambda: _trial(), max(3, repeats // 4)),
        "study_trials_per_second": _study_trials_per_second(max(1, repeats // 10)),
        # the refined study's grid: Gaussian roads, 10 % sensor noise
        "study_refined_trials_per_second": _study_trials_per_second(max(1, repeats // 20), "likelihood",
                                                                    "gaussian", 0.1),
    }
    # the refinement's goals, as ratios to Rozyn's update with its covariance
    out["refined_warm_per_rozyn_update"] = out["refined_update_warm_ms"] / out["update_120s_window_ms"]
    out["refined_cold_per_rozyn_update"] = out["refined_update_cold_ms"] / out["update_120s_window_ms"]
    out["budget_overhead_pct"] = 100.0 * (
        out["refined_update_warm_ms"] / out["refined_update_warm_without_budget_ms"] - 1.0)
    out["glitch_per_clean_update"] = out["glitch_update_warm_ms"] / out["refined_update_warm_ms"]
    out |= _full_car_figures(
        repeats, lambda: estimate(nxt, 100.0, vehicle, PipelineConfig(), speed, warm_start=warm),
        lambda: estimate(window, 100.0, vehicle, PipelineConfig(), speed))
    out |= _urban_figures(
        repeats, lambda: estimate(nxt, 100.0, vehicle, PipelineConfig(), speed, warm_start=warm),
        lambda: estimate(window, 100.0, vehicle, PipelineConfig(), speed))
    out |= _imu_figures(repeats)
    out["peak_rss_mb"] = _peak_rss_mb()
    out["goals"] = {"sim_100s_at_100hz_ms": 20.0, "update_120s_window_ms": 10.0,
                    "refined_update_warm_ms": 20.0, "refined_update_cold_ms": 60.0,
                    "refined_warm_per_rozyn_update": 2.5, "refined_cold_per_rozyn_update": 7.0,
                    "budget_overhead_pct": 30.0, "glitch_per_clean_update": 2.0,
                    "full_refined_warm_per_half": 3.0, "full_refined_cold_per_half": 3.0,
                    "urban_cold_per_constant": 1.5, "urban_warm_per_constant": 1.5}
    return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in out.items()}


def run_silent_sensor_bench(hours: float = 1.0, rate_hz: float = 1000.0, every_s: float = 300.0,
                            one_by_one: bool = False) -> dict[str, Any]:
    """Resident memory while one sensor is silent: ``hours`` of ``rate_hz`` front samples,
    the rear never heard, fed through ``add_batch`` a second at a time (as ``rozyn replay``
    feeds) or, ``one_by_one``, through ``add`` (as the node does).

    Returns:
        Resident set size [MB] and samples the front channel holds, every ``every_s`` of
        message time, and the growth over the second half of the run (flat: about 0).
    """
    from rozyn_estimator.online import OnlineEstimator

    online = OnlineEstimator(Vehicle())
    front = online._channels[0]
    per_s = round(rate_hz)
    noise = 9.81 + np.random.default_rng(0).standard_normal(per_s)
    rows = []
    for second in range(round(hours * 3600)):
        t = (second * per_s + np.arange(per_s)) * round(1e9 / rate_hz)
        if one_by_one:
            for stamp, value in zip(t.tolist(), noise.tolist(), strict=True):
                online.add(0, stamp, value)
        else:
            online.add_batch(np.zeros(per_s, np.int64), t, noise)
        if (second + 1) % round(every_s) == 0:
            rows.append({"message_time_s": second + 1, "rss_mb": round(_rss_mb(), 1),
                         "front_samples_held": int(front.stamps.size + len(front.new_stamps))})
    half = rows[len(rows) // 2]["rss_mb"]
    return {
        "fed": "add, one by one (the node)" if one_by_one else "add_batch, 1 s at a time (rozyn replay)",
        "rate_hz": rate_hz, "window_s": online.config.window_s, "status": online.health().message,
        "samples": rows, "rss_growth_second_half_mb": round(rows[-1]["rss_mb"] - half, 1),
    }


def _rss_mb() -> float:
    """Current resident set size (Linux: /proc; elsewhere the peak)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * resource.getpagesize() / 2**20
    except OSError:
        return _peak_rss_mb()


def _trial() -> None:
    from rozyn_estimator.tools.trial.run import run_trial

    run_trial(TrialSpec(), 1)


def _study_trials_per_second(repeats: int, method: str = "", amplitudes: str = "fixed",
                             noise_fraction: float = 0.0) -> float:
    """One core over the thesis grid's mix of measurement times (``rozyn study [--method]``)."""
    from rozyn_estimator.tools.study import bench_trials_per_second

    return bench_trials_per_second(repeats, method, amplitudes, noise_fraction)
