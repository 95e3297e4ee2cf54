"""``rozyn trial --model full``: seeded full-car runs (two road tracks, four corner
accelerometers) and Rozyn's stage of the full car on each; a table vs truth or JSON lines.

Methods: ``likelihood`` (the default: Rozyn's stage of the full car, then the full car's
likelihood refinement and its budget) and ``rozyn`` (Rozyn's stage alone, with its jackknife
and the tolerances' budget).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PipelineConfig
from rozyn_estimator.method.full import FULL_PARAM_NAMES, FullEstimate, estimate_full
from rozyn_estimator.tools.options import departure_values, vehicle_error_values
from rozyn_estimator.tools.trial import FULL_VEHICLE_ERRORS, departure_lines, parallel_map, parse_seeds
from rozyn_estimator.vehicle_full import FullVehicle, load_full_vehicle
from sim_node.departures import Departures
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

LABELS = ("mass [kg]", "roll inertia [kg m^2]", "pitch inertia [kg m^2]", "CoG from front axle [m]",
          "CoG left of centre [m]")
METHODS_FULL = ("likelihood", "rozyn")
NOISE_STREAM = 4  # the sensor noise's random stream per seed (the simulator's are 0-3)
_METHOD_LABELS = {"likelihood": "Rozyn's pipeline and the likelihood refinement", "rozyn": "Rozyn's pipeline"}


@dataclass(frozen=True)
class FullTrialSpec:
    """The conditions of a full-car trial; the seed picks the road (both tracks)."""

    sim: SimConfig  # model full; its seed is replaced per trial
    noise_fraction: float = 0.0  # white sensor noise, share of each channel's rms
    method: str = "likelihood"
    pipeline: PipelineConfig | None = None  # overrides the method's settings (rozyn study's)
    told: FullVehicle | None = None  # the vehicle the estimator is told (None: the simulated one)

    @property
    def plant(self) -> FullVehicle:
        """The simulated vehicle (the truth)."""
        v = self.sim.plant_vehicle
        assert isinstance(v, FullVehicle)
        return v

    @property
    def vehicle(self) -> FullVehicle:
        """The vehicle the estimator is told."""
        return self.told if self.told is not None else self.plant

    def pipeline_config(self) -> PipelineConfig:
        """The estimator's settings: ``pipeline``, else the method's."""
        return self.pipeline or METHODS[self.method]

    @property
    def truth(self) -> np.ndarray:
        v = self.plant
        return np.array([v.sprung_mass_kg, v.roll_inertia_kgm2, v.pitch_inertia_kgm2, v.cog_from_front_axle_m,
                         v.cog_lateral_m])


@dataclass(frozen=True)
class FullTrialResult:
    seed: int
    estimate: FullEstimate
    truth: np.ndarray
    sim_ms: float

    def to_dict(self) -> dict[str, Any]:
        """The JSON record of ``rozyn trial --model full --json``."""
        out: dict[str, Any] = {"seed": self.seed, "model": "full"}
        out.update(self.estimate.to_dict())
        out["truth"] = dict(zip(FULL_PARAM_NAMES, self.truth.tolist(), strict=True))
        return out


def spec_from_args(args: argparse.Namespace) -> FullTrialSpec:
    """The full-car trial the ``rozyn trial`` options describe (refusing what it cannot do)."""
    if args.method not in METHODS_FULL:
        raise ConfigError(f"method: the full car has {', '.join(METHODS_FULL)}; got {args.method!r}")
    vehicle = load_full_vehicle(args.vehicle) if args.vehicle else FullVehicle()
    if args.road == "free-decay":
        raise ConfigError("road: --model full drives over ISO 8608 or Laplace roads (free decay: the tests)")
    road = RoadSpec(kind=args.road, road_class=args.road_class, amplitudes=args.amplitudes,
                    laplace_nu=args.laplace_nu, waviness=args.waviness)
    sim = SimConfig(model="full", full_vehicle=vehicle, road=road, speed_kmh=args.speed_kmh,
                    rate_hz=args.rate_hz, noise_std_mps2=args.noise_std_mps2, duration_s=args.duration_s,
                    departures=Departures(**departure_values(args)))
    return FullTrialSpec(sim=sim, noise_fraction=args.noise_fraction, method=args.method,
                         told=told_vehicle(vehicle, vehicle_error_values(args)))


def told_errors(spec: FullTrialSpec) -> dict[str, float]:
    """The ``*_error`` shares the estimator is told (of ``spec.told`` against the plant)."""
    if spec.told is None:
        return {}
    return {key: getattr(spec.told, field)[0] / getattr(spec.plant, field)[0] - 1.0
            for key, field in FULL_VEHICLE_ERRORS.items()}


def told_vehicle(vehicle: FullVehicle, errors: dict[str, float]) -> FullVehicle | None:
    """``vehicle`` with each ``errors`` share (the ``--*-error`` options) on its per-corner values,
    as the estimator is told it; None when every error is zero."""
    changes: dict[str, Any] = {}
    for key, error in errors.items():
        if error != 0.0:
            if not -1.0 < error < 10.0:
                raise ConfigError(f"{key}: must lie in (-1, 10), got {error!r}")
            field = FULL_VEHICLE_ERRORS[key]
            changes[field] = tuple(x * (1.0 + error) for x in getattr(vehicle, field))
    return dataclasses.replace(vehicle, **changes) if changes else None


def simulate_full(spec: FullTrialSpec, seed: int) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], float]:
    """One seeded full-car run with its relative noise (from its own stream): (accelerations
    (n, 4), speed per sample [m/s], the channels' corners, the time it took [ms])."""
    started = time.perf_counter()
    sim = dataclasses.replace(spec.sim, seed=seed)
    block = Simulation(sim).run(sim.duration_s)
    accel = block.accel_mps2
    if spec.noise_fraction > 0:
        rms = accel.std(axis=0)
        # its own stream: the road's are 0 and 1, the simulator's noise 2, the right track's 3 (that
        # one made the noise a copy of the right track's independent part)
        noise = np.random.default_rng([seed, NOISE_STREAM]).standard_normal(accel.shape)
        accel = accel + noise * (spec.noise_fraction * rms)
    return accel, block.speed_mps, tuple(block.channels), (time.perf_counter() - started) * 1e3


def run_full_trial(spec: FullTrialSpec, seed: int) -> FullTrialResult:
    """Simulate one seeded full-car run and estimate."""
    accel, speed, channels, sim_ms = simulate_full(spec, seed)
    cfg = spec.pipeline_config()
    est = estimate_full(accel, spec.sim.rate_hz, spec.vehicle, cfg, speed, sensors=channels)
    return FullTrialResult(seed, est, spec.truth, sim_ms)


def _run(item: tuple[FullTrialSpec, int]) -> FullTrialResult:
    return run_full_trial(*item)


def run(args: argparse.Namespace) -> int:
    """``rozyn trial --model full``."""
    spec = spec_from_args(args)
    seeds = parse_seeds(args.seeds if args.seeds is not None else str(args.seed))
    results = []
    for result in parallel_map(_run, [(spec, s) for s in seeds], args.jobs,
                               not args.quiet and sys.stderr.isatty(), "trial"):
        results.append(result)
        if args.json:
            print(json.dumps(result.to_dict()), flush=True)
    if not args.json:
        print(format_full_trials(spec, results))
    return 0


def format_full_trials(spec: FullTrialSpec, results: Sequence[FullTrialResult]) -> str:
    s = spec.sim
    lines = [f"full car: {s.road.kind} class {s.road.road_class} ({s.road.amplitudes}), two tracks "
             f"({s.track_coherence} coherence), {s.speed_kmh:g} km/h, {s.duration_s:g} s at "
             f"{s.rate_hz:g} Hz, {_METHOD_LABELS[spec.method]}, {len(results)} seed(s)",
             *departure_lines(s.departures, told_errors(spec), full_car=True), ""]
    ok = [r for r in results if r.estimate.ok and r.estimate.params is not None]
    lines.append(f"{'parameter':<26}{'truth':>9}{'mean':>11}{'spread':>10}{'reported std':>14}")
    if ok:
        p = np.array([r.estimate.params for r in ok])
        std = np.array([r.estimate.std if r.estimate.std is not None else np.full(5, np.nan) for r in ok])
        spread = p.std(axis=0, ddof=1) if len(ok) > 1 else np.full(5, np.nan)
        for i, label in enumerate(LABELS):
            lines.append(f"{label:<26}{spec.truth[i]:>9.4g}{p[:, i].mean():>11.5g}{spread[i]:>10.4g}"
                         f"{np.sqrt(np.mean(std[:, i] ** 2)):>14.4g}")
    lines += ["", f"failures: {len(results) - len(ok)} of {len(results)}"]
    lines += [f"  seed {r.seed}: {r.estimate.reason}" for r in results if not r.estimate.ok][:5]
    fits = [r.estimate.refinement.model_fit for r in ok if r.estimate.refinement is not None
            and r.estimate.refinement.model_fit is not None]
    if fits:
        lines.append(f"model check: the full-car model does not fit in {sum(not f.ok for f in fits)} of "
                     f"{len(fits)} (median p = {np.median([f.p_value for f in fits]):.2g})")
    fallbacks = sum(1 for r in ok if r.estimate.refinement is not None and r.estimate.stage == "rozyn")
    if fallbacks:
        lines.append(f"refinement failed, Rozyn's estimate published: {fallbacks} of {len(results)}")
    return "\n".join(lines)
