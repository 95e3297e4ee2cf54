"""``rozyn compare --model full``: the full car's methods side by side on the same seeded runs,
and its acceptance suite (issue 13).

Each seed's run (two road tracks, four corner accelerometers) is simulated once and every
method (``likelihood``, ``rozyn``) estimates from the very same samples. Per method and
parameter: mean, bias (per cent; the lateral CoG in millimetres), spread, the mean
reported std, 95 % coverage, failures and the median time per estimate; with
``--suite acceptance`` each case's verdict against its bars. ``--vehicle-preset second``
swaps in a second, clearly different full car; the suites are :mod:`.full_suites`'s.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS
from rozyn_estimator.method.full import FULL_PARAM_NAMES, FullEstimate, estimate_full
from rozyn_estimator.tools.full_suites import (
    FULL_PRESETS,
    FULL_SUITES,
    FullBars,
    FullCase,
    acceptance_cases,
    mismatch_cases,
)
from rozyn_estimator.tools.options import departure_values, vehicle_error_values
from rozyn_estimator.tools.trial import parallel_map, parse_seeds
from rozyn_estimator.tools.trial_full import METHODS_FULL, FullTrialSpec, simulate_full, told_vehicle
from rozyn_estimator.vehicle_full import load_full_vehicle
from sim_node.departures import Departures
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig

LABELS = ("m [kg]", "I_xx [kg m^2]", "I_yy [kg m^2]", "l_f [m]", "y_c [m]")


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
    rms_error: np.ndarray = field(default_factory=lambda: np.full(5, np.nan))  # the parameters' units

    def missed(self, bars: FullBars) -> list[str]:
        """Which bars it misses (empty: all met)."""
        out = [f"failures {self.failures}/{self.n}"] if self.failures > bars.failure_share * self.n else []
        lo, hi = bars.coverage
        for i, name in enumerate(FULL_PARAM_NAMES):
            limit = bars.bias_lateral_m if i == 4 else bars.bias_pct
            if limit is not None and not abs(self.bias[i]) <= limit:
                out.append(f"bias {name} {self.bias[i]:+.3g}")
            if not lo <= self.coverage_95[i] <= hi:
                out.append(f"coverage {name} {self.coverage_95[i]:.2f}")
            limit = bars.max_std_per_rms
            if limit is not None and not self.mean_reported_std[i] <= limit * self.rms_error[i]:
                out.append(f"std {name} {self.mean_reported_std[i] / self.rms_error[i]:.2g}x its rms error")
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
        median_ms=float(np.median([e.elapsed_ms for e in ok])), rms_error=np.sqrt(np.mean(err**2, axis=0)))


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


_HALF_ONLY = {"speed_variation": 0.0, "endless_road": False, "sensor_offsets_m": None}


def run(args: argparse.Namespace) -> int:
    """``rozyn compare --model full``."""
    given = [f"--{k.replace('_', '-')}" for k, default in _HALF_ONLY.items()
             if getattr(args, k, default) != default]
    if given or tuple(getattr(args, "bias_mps2", (0.0, 0.0))) != (0.0, 0.0):
        raise ConfigError(f"{', '.join(given) or '--bias-mps2'}: not available with --model full (the half "
                          "car's sensor options)")
    if args.suite not in (None, *FULL_SUITES):
        raise ConfigError(f"suite: --model full has the suites {', '.join(FULL_SUITES)}; got {args.suite!r}")
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    methods = [m for m in methods if m in METHODS_FULL] if args.methods_defaulted else methods
    vehicle = load_full_vehicle(args.vehicle) if args.vehicle else FULL_PRESETS[args.vehicle_preset]
    if args.suite == "acceptance":
        cases = acceptance_cases(vehicle)
    elif args.suite == "mismatch":
        cases = mismatch_cases(vehicle)
    else:
        road = RoadSpec(kind=args.road, road_class=args.road_class, amplitudes=args.amplitudes,
                        laplace_nu=args.laplace_nu, waviness=args.waviness)
        sim = SimConfig(model="full", full_vehicle=vehicle, road=road, speed_kmh=args.speed_kmh,
                        duration_s=args.duration_s, rate_hz=args.rate_hz,
                        departures=Departures(**departure_values(args)))
        told = told_vehicle(vehicle, vehicle_error_values(args))
        cases = [FullCase("as given", FullTrialSpec(sim=sim, noise_fraction=args.noise, told=told))]
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
