"""``rozyn compare --model full``: the full car's methods side by side on the same seeded runs,
and its acceptance suite (issue 13).

Each seed's run (two road tracks, four corner accelerometers) is simulated once and every
method (``likelihood``, ``rozyn``) estimates from the very same samples. Per method and
parameter: mean, bias (per cent; the lateral CoG in millimetres), spread, the mean
reported std, 95 % coverage, failures and the median time per estimate; with
``--suite acceptance`` each case's verdict against its bars. ``--vehicle-preset second``
swaps in a second, clearly different full car (:data:`SECOND_FULL_VEHICLE`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS
from rozyn_estimator.method.full import FULL_PARAM_NAMES, FullEstimate, estimate_full
from rozyn_estimator.tools.trial import parallel_map, parse_seeds
from rozyn_estimator.tools.trial_full import METHODS_FULL, FullTrialSpec, simulate_full
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle, load_full_vehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig

# A second full car, clearly different from Table 5-1 extended: an SUV's mass and inertias,
# a longer wheelbase and wider tracks (the rear wider), its CoG 3 cm left of the centreline,
# stiffer tyres and suspension, heavier wheels, anti-roll bars on both axles.
SECOND_FULL_VEHICLE = FullVehicle(
    sprung_mass_kg=1800.0, pitch_inertia_kgm2=3200.0, roll_inertia_kgm2=650.0, cog_from_front_axle_m=1.55,
    cog_lateral_m=0.03, wheelbase_m=3.2, track_front_m=1.62, track_rear_m=1.65,
    unsprung_mass_kg=(27.5, 27.5, 37.5, 37.5), tyre_stiffness_npm=(130e3, 130e3, 140e3, 140e3),
    tyre_damping_nspm=(50.0,) * 4, suspension_stiffness_npm=(30e3, 30e3, 45e3, 45e3),
    suspension_damping_nspm=(1900.0, 1900.0, 2250.0, 2250.0), anti_roll_stiffness_front_nmprad=25e3,
    anti_roll_stiffness_rear_nmprad=10e3, sensor_x_m=(0.0, 0.0, 3.2, 3.2),
    sensor_y_m=(0.81, -0.81, 0.825, -0.825),
)
FULL_PRESETS = {"table5-1": FullVehicle(), "second": SECOND_FULL_VEHICLE}
LABELS = ("m [kg]", "I_xx [kg m^2]", "I_yy [kg m^2]", "l_f [m]", "y_c [m]")


@dataclass(frozen=True)
class FullBars:
    """A case's bars: |bias| in per cent for m, I_xx, I_yy, l_f and in metres for y_c."""

    bias_pct: float = 0.5
    bias_lateral_m: float = 0.005
    coverage: tuple[float, float] = (0.90, 0.98)
    failure_share: float = 0.01


@dataclass(frozen=True)
class FullCase:
    label: str
    spec: FullTrialSpec
    bars: FullBars | None = None


@dataclass(frozen=True)
class FullSummary:
    """Statistics of one method over a case's seeds, per parameter in FULL_PARAM_NAMES order."""

    n: int
    failures: int
    truth: np.ndarray
    mean: np.ndarray
    spread: np.ndarray
    bias: np.ndarray  # per cent; the lateral CoG in metres
    mean_reported_std: np.ndarray
    coverage_95: np.ndarray
    median_ms: float

    def missed(self, bars: FullBars) -> list[str]:
        """Which bars it misses (empty: all met)."""
        out = [f"failures {self.failures}/{self.n}"] if self.failures > bars.failure_share * self.n else []
        lo, hi = bars.coverage
        for i, name in enumerate(FULL_PARAM_NAMES):
            limit = bars.bias_lateral_m if i == 4 else bars.bias_pct
            if not abs(self.bias[i]) <= limit:
                out.append(f"bias {name} {self.bias[i]:+.3g}")
            if not lo <= self.coverage_95[i] <= hi:
                out.append(f"coverage {name} {self.coverage_95[i]:.2f}")
        return out


def summarise_full(estimates: Sequence[FullEstimate], truth: np.ndarray) -> FullSummary:
    ok = [e for e in estimates if e.ok and e.params is not None and e.std is not None]
    nan = np.full(5, np.nan)
    if not ok:
        return FullSummary(len(estimates), len(estimates), truth, nan, nan, nan, nan, nan, float("nan"))
    p = np.array([e.params for e in ok])
    std = np.array([e.std for e in ok])
    err = p - truth
    bias = 100.0 * err.mean(axis=0) / np.where(truth == 0, 1.0, np.abs(truth))
    bias[4] = err[:, 4].mean()
    return FullSummary(
        n=len(estimates), failures=len(estimates) - len(ok), truth=truth, mean=p.mean(axis=0),
        spread=p.std(axis=0, ddof=1) if len(ok) > 1 else nan, bias=bias,
        mean_reported_std=np.sqrt(np.mean(std**2, axis=0)),
        coverage_95=np.mean(np.abs(err) <= 1.96 * std, axis=0),
        median_ms=float(np.median([e.elapsed_ms for e in ok])))


def acceptance_cases(vehicle: FullVehicle) -> list[FullCase]:
    """Issue 13's cases on ``vehicle`` known exactly (the estimator's own statistics): Gaussian
    ISO A with 10 % sensor noise for 120 s at 30, 50, 70 and 100 km/h, and the Laplace road
    (ν = 1) at 100 km/h."""
    exact = dataclasses.replace(vehicle, tolerances=cast(FullTolerances, FullTolerances.none()))

    def case(label: str, road: RoadSpec, speed_kmh: float) -> FullCase:
        sim = SimConfig(model="full", full_vehicle=exact, road=road, speed_kmh=speed_kmh, duration_s=120.0)
        return FullCase(label, FullTrialSpec(sim=sim, noise_fraction=0.1), FullBars())

    gaussian = RoadSpec(amplitudes="gaussian")
    return [case(f"Gaussian ISO A, {v:g} km/h", gaussian, v) for v in (30.0, 50.0, 70.0, 100.0)] + \
        [case("Laplace road (nu 1), 100 km/h", RoadSpec(kind="laplace", laplace_nu=1.0), 100.0)]


def _run_seed(item: tuple[FullTrialSpec, tuple[str, ...], int]) -> dict[str, FullEstimate]:
    spec, methods, seed = item
    accel, speed, channels, _ = simulate_full(spec, seed)
    return {m: estimate_full(accel, spec.sim.rate_hz, spec.vehicle, METHODS[m], speed, sensors=channels)
            for m in methods}


def compare_full(spec: FullTrialSpec, methods: Sequence[str], seeds: Sequence[int], jobs: int | None = None,
                 progress: bool = False) -> dict[str, list[FullEstimate]]:
    """Every method on each seed's run (simulated once); estimates per method in seed order."""
    unknown = [m for m in methods if m not in METHODS_FULL]
    if unknown:
        raise ConfigError(f"methods: the full car has {', '.join(METHODS_FULL)}; got {', '.join(unknown)}")
    out: dict[str, list[FullEstimate]] = {m: [] for m in methods}
    work = [(spec, tuple(methods), int(s)) for s in seeds]
    for per_method in parallel_map(_run_seed, work, jobs, progress, "seed"):
        for m, est in per_method.items():
            out[m].append(est)
    return out


def format_full_case(case: FullCase, results: dict[str, list[FullEstimate]]) -> str:
    """A table of one case: a row per method and parameter, and its verdicts."""
    s, truth = case.spec.sim, case.spec.truth
    head = (f"{case.label} — full car, {s.road.kind} ({s.road.amplitudes}), {s.speed_kmh:g} km/h, "
            f"{s.duration_s:g} s, {case.spec.noise_fraction:.0%} noise; truth "
            + " / ".join(f"{x:g}" for x in truth) + f"; {len(next(iter(results.values())))} seeds")
    cols = ("method", "parameter", "mean", "bias", "spread", "reported std", "95 % cover", "failures", "ms")
    rows, verdicts = [], []
    for method, estimates in results.items():
        sm = summarise_full(estimates, truth)
        for i, label in enumerate(LABELS):
            bias = f"{sm.bias[i] * 1e3:+.2f} mm" if i == 4 else f"{sm.bias[i]:+.3f} %"
            rows.append((method if i == 0 else "", label, f"{sm.mean[i]:.5g}", bias, f"{sm.spread[i]:.3g}",
                         f"{sm.mean_reported_std[i]:.3g}", f"{sm.coverage_95[i] * 100:.0f} %",
                         f"{sm.failures}/{sm.n}" if i == 0 else "", f"{sm.median_ms:.0f}" if i == 0 else ""))
        if case.bars is not None and method == "likelihood":
            missed = sm.missed(case.bars)
            verdict = "meets the case's bars" if not missed else "MISSES " + "; ".join(missed)
            verdicts.append(f"{method}: {verdict}")
    widths = [max(len(c), *(len(r[j]) for r in rows)) for j, c in enumerate(cols)]
    line = "  ".join(f"{{:<{w}}}" if j < 2 else f"{{:>{w}}}" for j, w in enumerate(widths)).format
    tail = ["", *verdicts] if verdicts else []
    return "\n".join([head, "", line(*cols), *(line(*r) for r in rows), *tail])


def case_records(case: FullCase, results: dict[str, list[FullEstimate]]) -> list[dict[str, object]]:
    """JSON-ready statistics of one case, one record per method."""
    out = []
    for method, estimates in results.items():
        sm = summarise_full(estimates, case.spec.truth)
        rec: dict[str, object] = {"case": case.label, "model": "full", "method": method, "n": sm.n,
                                  "failures": sm.failures, "median_ms": sm.median_ms}
        for key in ("truth", "mean", "spread", "bias", "mean_reported_std", "coverage_95"):
            rec[key] = dict(zip(FULL_PARAM_NAMES, np.asarray(getattr(sm, key), float).tolist(), strict=True))
        if case.bars is not None:
            rec["missed_bars"] = sm.missed(case.bars)
        out.append(rec)
    return out


_HALF_ONLY = {"damper_ratio": 1.0, "spring_progression": 0.0, "lowpass_hz": 0.0, "time_offset_s": 0.0,
              "speed_variation": 0.0, "endless_road": False, "sensor_offsets_m": None}


def run(args: argparse.Namespace) -> int:
    """``rozyn compare --model full``."""
    given = [f"--{k.replace('_', '-')}" for k, default in _HALF_ONLY.items()
             if getattr(args, k, default) != default]
    if given or tuple(getattr(args, "gain_error", (0.0, 0.0))) != (0.0, 0.0):
        raise ConfigError(f"{', '.join(given) or '--gain-error'}: not available with --model full (the half "
                          "car's departures and sensor options)")
    if args.suite not in (None, "acceptance"):
        raise ConfigError(f"suite: --model full has the acceptance suite; got {args.suite!r}")
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    methods = [m for m in methods if m in METHODS_FULL] if args.methods_defaulted else methods
    vehicle = load_full_vehicle(args.vehicle) if args.vehicle else FULL_PRESETS[args.vehicle_preset]
    if args.suite == "acceptance":
        cases = acceptance_cases(vehicle)
    else:
        road = RoadSpec(kind=args.road, road_class=args.road_class, amplitudes=args.amplitudes,
                        laplace_nu=args.laplace_nu, waviness=args.waviness)
        sim = SimConfig(model="full", full_vehicle=vehicle, road=road, speed_kmh=args.speed_kmh,
                        duration_s=args.duration_s, rate_hz=args.rate_hz)
        cases = [FullCase("as given", FullTrialSpec(sim=sim, noise_fraction=args.noise))]
    seeds = parse_seeds(args.seeds)
    progress = not args.quiet and sys.stderr.isatty()
    for k, case in enumerate(cases):
        results = compare_full(case.spec, methods, seeds, jobs=args.jobs, progress=progress)
        if args.format == "json":
            for rec in case_records(case, results):
                print(json.dumps(rec), flush=True)
        else:
            print(("\n" if k else "") + format_full_case(case, results), flush=True)
    return 0
