"""Simulated trials: one seeded run of the half car through the estimator.

The workhorse of ``rozyn trial``, the study, the method comparison and the benchmark.
As a tool it imports both the plant (``sim_node``) and the estimator; the estimator's
own modules never import the plant (DESIGN.md).
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PARAM_NAMES, Estimate, PipelineConfig, estimate
from rozyn_estimator.parameters import check, param
from rozyn_estimator.vehicle import Vehicle
from sim_node.departures import Departures
from sim_node.road import RoadSpec
from sim_node.simulation import SimBlock, SimConfig, Simulation

TRIAL_ROADS = ("iso", "laplace", "free-decay")
# The estimator's wrong vehicle values: TrialSpec field -> the Vehicle fields it scales by
# (1 + error), both axles. The simulated vehicle stays the true one.
VEHICLE_ERRORS: dict[str, tuple[str, str]] = {
    "stiffness_error": ("suspension_stiffness_front_npm", "suspension_stiffness_rear_npm"),
    "damping_error": ("suspension_damping_front_nspm", "suspension_damping_rear_nspm"),
    "tyre_stiffness_error": ("tyre_stiffness_front_npm", "tyre_stiffness_rear_npm"),
    "tyre_damping_error": ("tyre_damping_front_nspm", "tyre_damping_rear_nspm"),
    "unsprung_mass_error": ("unsprung_mass_front_kg", "unsprung_mass_rear_kg"),
}
# the same errors on the full car's per-corner values (FullVehicle's fields), all four corners
FULL_VEHICLE_ERRORS: dict[str, str] = {
    "stiffness_error": "suspension_stiffness_npm", "damping_error": "suspension_damping_nspm",
    "tyre_stiffness_error": "tyre_stiffness_npm", "tyre_damping_error": "tyre_damping_nspm",
    "unsprung_mass_error": "unsprung_mass_kg",
}


def departure_lines(d: Departures, told_errors: dict[str, float], full_car: bool = False) -> list[str]:
    """How a run departs from the estimator's model (``told_errors``: the ``*_error`` shares the
    estimator is told), as report lines (none: it does not)."""
    gains = d.corner_gains if full_car else d.gains
    gain_text = f"{d.gain_error_front * 100:+g} % front, {d.gain_error_rear * 100:+g} % rear"
    if full_car and gains is not None:
        gain_text = " / ".join(f"{(g - 1) * 100:+g}" for g in gains) + " % (FL/FR/RL/RR)"
    plant = [text for on, text in (
        (d.damper_ratio != 1.0, f"dampers {d.damper_ratio:g}x stiffer in rebound than in compression"),
        (d.spring_progression != 0.0, f"progressive springs, +{d.spring_progression * 100:g} % force at "
                                      f"{d.spring_reference_m * 1e3:g} mm"),
        (gains is not None, f"sensor gain errors {gain_text}"),
        (d.time_offset_s != 0.0, f"rear sensor{'s' if full_car else ''} {d.time_offset_s * 1e3:+g} ms late"),
        (d.lowpass_hz > 0.0, f"{d.lowpass_hz:g} Hz low-pass in every sensor"),
    ) if on]
    told = [f"{key.removesuffix('_error').replace('_', ' ')} {error * 100:+g} %"
            for key, error in told_errors.items() if error != 0.0]
    return ([f"simulated vehicle departs: {'; '.join(plant)}"] if plant else []) + \
        ([f"estimator told wrong: {'; '.join(told)}"] if told else [])


def _told(what: str) -> str:
    return f"the estimator is told the {what} * (1 + error), both axles; in (-1, 10)"


@dataclass(frozen=True)
class TrialSpec:
    """The conditions of a trial; the seed picks the road.

    Checked here: every field's type, and the trial's own rules (road, method, duration,
    relative noise, the estimator's vehicle errors); errors name the field. The ranges of
    the road, sensor and departure settings are the simulator's (:class:`SimConfig`,
    :class:`RoadSpec`, :class:`Departures`), checked as this spec's ``sim_config``.

    Two ways to depart from the estimator's model: ``departures`` change the simulated
    plant and sensors (the estimator is not told), the ``*_error`` fields change what the
    estimator is told of the vehicle (the simulated one stays true).
    """

    road: str = param("iso", "road model", choices=TRIAL_ROADS)
    road_class: str = param("A", "ISO 8608 class of the (base) road, A..H")
    amplitudes: str = param("fixed", "fixed: the thesis' generator; gaussian: a true Gaussian road",
                            choices=("fixed", "gaussian"))
    laplace_nu: float = param(1.0, "Laplace road: variance of the section gamma variable")
    waviness: float = param(2.0, "ISO 8608 waviness w")
    speed_kmh: float = param(100.0, "vehicle speed", unit="km/h")
    duration_s: float = param(100.0, "measurement time", unit="s", low=0.0, open_low=True)
    rate_hz: float = param(100.0, "accelerometer rate", unit="Hz")
    noise_std_mps2: float = param(0.0, "white sensor noise", unit="m/s^2")
    noise_fraction: float = param(0.0, "white noise std as a share of each channel's rms", low=0.0)
    bias_mps2: tuple[float, float] = param((0.0, 0.0), "constant sensor offsets (front, rear)", unit="m/s^2",
                                           length=2)
    speed_variation: float = param(0.0, "relative amplitude of a sinusoidal speed change")
    speed_period_s: float = param(60.0, "period of the speed change", unit="s")
    periodic: bool = param(True, "road period = the record's distance (thesis eq 4-7); false: endless road")
    vehicle: Vehicle = param(description="the true vehicle", default_factory=Vehicle)
    departures: Departures = param(description="the simulated plant's and sensors' departures from the "
                                   "estimator's model", default_factory=Departures)
    stiffness_error: float = param(0.0, _told("suspension stiffness k_s"))
    damping_error: float = param(0.0, _told("suspension damping c_s"))
    tyre_stiffness_error: float = param(0.0, _told("tyre stiffness k_t"))
    tyre_damping_error: float = param(0.0, _told("tyre damping c_t"))
    unsprung_mass_error: float = param(0.0, _told("unsprung mass m_t"))
    method: str = param("rozyn", "estimation method", choices=tuple(METHODS))
    pipeline: PipelineConfig | None = None  # overrides the method's settings

    def __post_init__(self) -> None:
        errors = tuple((name, lambda t, n=name: -1.0 < getattr(t, n) < 10.0, "must lie in (-1, 10)")
                       for name in VEHICLE_ERRORS)
        check(self, (
            *errors,
            ("pipeline", lambda t: t.pipeline is None or isinstance(t.pipeline, PipelineConfig),
             "expected PipelineConfig settings or None"),
        ))
        self.sim_config(0)  # validates road, sim and departure settings

    def sim_config(self, seed: int) -> SimConfig:
        if self.road == "free-decay":
            road = RoadSpec(kind="flat")
        else:
            road = RoadSpec(
                kind=self.road, road_class=self.road_class, amplitudes=self.amplitudes,
                laplace_nu=self.laplace_nu, waviness=self.waviness,
            )
        return SimConfig(
            vehicle=self.vehicle, road=road, seed=seed, speed_kmh=self.speed_kmh,
            speed_variation=self.speed_variation, speed_period_s=self.speed_period_s,
            rate_hz=self.rate_hz, noise_std_mps2=self.noise_std_mps2, bias_mps2=self.bias_mps2,
            duration_s=self.duration_s if self.periodic else 0.0, departures=self.departures,
        )

    def pipeline_config(self, method: str | None = None) -> PipelineConfig:
        """The estimator's settings for ``method`` (default: this spec's method)."""
        cfg = METHODS[method] if method is not None else (self.pipeline or METHODS[self.method])
        if self.road == "free-decay":
            # The signal is itself the free decay (thesis section 5-1): no correlation, and
            # nothing for a road-driven likelihood to refine.
            cfg = cfg.replace(
                correlation="free-decay", variance="none", min_duration_s=min(cfg.min_duration_s, 0.5),
                refine="none",
            )
        return cfg

    @property
    def estimator_vehicle(self) -> Vehicle:
        """The vehicle the estimator is told: the true one with the ``*_error`` fields applied."""
        v = self.vehicle
        changes = {name: getattr(v, name) * (1.0 + error) for key, names in VEHICLE_ERRORS.items()
                   if (error := getattr(self, key)) != 0.0 for name in names}
        return v.replace(**changes) if changes else v

    def replace(self, **changes: Any) -> TrialSpec:
        return dataclasses.replace(self, **changes)

    @property
    def truth(self) -> np.ndarray:
        v = self.vehicle
        return np.array([v.sprung_mass_kg, v.pitch_inertia_kgm2, v.cog_from_front_axle_m])


@dataclass(frozen=True)
class TrialResult:
    seed: int
    estimate: Estimate
    truth: np.ndarray
    sim_ms: float

    def to_dict(self) -> dict[str, Any]:
        """The JSON record of ``rozyn trial --json``."""
        out: dict[str, Any] = {"seed": self.seed}
        out.update(self.estimate.to_dict())
        out["truth"] = dict(zip(PARAM_NAMES, self.truth.tolist(), strict=True))
        return out


def simulate(spec: TrialSpec, seed: int) -> SimBlock:
    """The seeded run's accelerometer samples, with the spec's relative sensor noise added.

    The relative noise (``noise_fraction``) is white, with a standard deviation of that
    share of each channel's rms as simulated (about its mean: gravity and bias do not
    count), from its own random stream.
    """
    block = Simulation(spec.sim_config(seed)).run(spec.duration_s)
    if spec.noise_fraction > 0:
        accel = block.accel_mps2
        rms = accel.std(axis=0)
        noise = np.random.default_rng([seed, 3]).standard_normal(accel.shape) * (spec.noise_fraction * rms)
        block = dataclasses.replace(block, accel_mps2=accel + noise)
    return block


def run_trial(spec: TrialSpec, seed: int) -> TrialResult:
    """Simulate one seeded run and estimate from it."""
    started = time.perf_counter()
    block = simulate(spec, seed)
    sim_ms = (time.perf_counter() - started) * 1e3
    est = estimate_block(spec, block)
    return TrialResult(seed=seed, estimate=est, truth=spec.truth, sim_ms=sim_ms)


def estimate_block(spec: TrialSpec, block: SimBlock, method: str | None = None) -> Estimate:
    """Run the estimator of ``method`` (default: the spec's) on a simulated block.

    The estimator is told the speed per sample (as from a speed topic) and the spec's
    estimator vehicle (which may carry suspension errors).
    """
    return estimate(block.accel_mps2, spec.rate_hz, spec.estimator_vehicle, spec.pipeline_config(method),
                    speed_mps=block.speed_mps)


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


@dataclass(frozen=True)
class Summary:
    """Statistics of a set of trials, per parameter in PARAM_NAMES order (a full car's rows in
    ``rozyn study --model full``: FULL_PARAM_NAMES)."""

    n: int
    failures: int
    truth: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    bias_pct: np.ndarray
    within_6pct: np.ndarray  # share of successful trials within 6 % of truth
    mean_reported_std: np.ndarray  # NaN when no covariance was reported
    median_ms: float
    coverage_95: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # truth within ±1.96 std
    rms_error: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # √mean (estimate - truth)²
    model_warn_share: float = float("nan")  # refined estimates whose model-fit check warned


def summarise(results: Iterable[TrialResult]) -> Summary:
    results = list(results)
    ok = [r for r in results if r.estimate.ok]
    truth = results[0].truth if results else np.full(3, np.nan)
    k = len(truth)  # the parameters: three, or a full car's five (rozyn study --model full)
    if not ok:
        nan = np.full(k, np.nan)
        return Summary(len(results), len(results), truth, nan, nan, nan, nan, nan, float("nan"))
    p = np.array([r.estimate.params for r in ok])
    stds = np.array([r.estimate.std if r.estimate.std is not None else np.full(k, np.nan) for r in ok])
    return Summary(
        n=len(results),
        failures=len(results) - len(ok),
        truth=truth,
        mean=p.mean(axis=0),
        std=p.std(axis=0, ddof=1) if len(ok) > 1 else np.zeros(k),
        bias_pct=(p.mean(axis=0) / truth - 1.0) * 100.0,
        within_6pct=np.mean(np.abs(p / truth - 1.0) <= 0.06, axis=0),
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
