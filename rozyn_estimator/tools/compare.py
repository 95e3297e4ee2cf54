"""``rozyn compare``: estimation methods side by side on the same simulated runs.

Each seed's run is simulated once and every method estimates from the very same
samples, so differences between methods are the methods', not the roads'. Per method
and parameter it reports the mean, the bias against the truth, the spread over seeds,
the mean reported standard deviation, how often the 95 % interval from the reported
covariance covers the truth, the failures and the median time per estimate.

Suites run named sets of cases (``--suite``, see :mod:`rozyn_estimator.tools.suites`):
``issue6``, ``acceptance``, ``robustness`` and ``mismatch`` (vehicles that depart from the
model, with tolerances that contain the departures). ``--vehicle-preset second`` swaps in
a second, clearly different vehicle.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator, Sequence

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PARAM_NAMES
from rozyn_estimator.tools.options import (
    add_departure_options,
    add_run_options,
    add_vehicle_error_options,
    departure_values,
    vehicle_error_values,
)
from rozyn_estimator.tools.suites import SUITES, VEHICLE_PRESETS, Bars, Case, suite
from rozyn_estimator.tools.trial import (
    TRIAL_ROADS,
    Summary,
    TrialResult,
    TrialSpec,
    estimate_block,
    parallel_map,
    parse_seeds,
    simulate,
    summarise,
)
from rozyn_estimator.vehicle import load_vehicle
from sim_node.departures import Departures

HELP = "run several methods on the same seeded runs: bias, std, 95 %% coverage, failures, time"
DESCRIPTION = (
    "Simulate seeded runs once and estimate from each with several methods (default: the "
    "thesis' method, Rozyn's with eq 2-21 and eq 2-22, Rozyn + the likelihood refinement, and "
    "the likelihood on auto-spectra only). Prints per method and parameter: mean, bias, spread, "
    "reported std, 95 % coverage, failures and time per estimate. --suite runs issue 6's cases."
)
DEFAULT_METHODS = ("thesis", "rozyn-eq2-21", "rozyn", "likelihood", "likelihood-auto")
LABELS = ("m [kg]", "I_yy [kg m^2]", "l_f [m]")

def _run_seed(args: tuple[TrialSpec, Sequence[str], int]) -> dict[str, TrialResult]:
    spec, methods, seed = args
    block = simulate(spec, seed)
    return {m: TrialResult(seed, estimate_block(spec, block, m), spec.truth, 0.0) for m in methods}


def compare(
    spec: TrialSpec, methods: Sequence[str], seeds: Sequence[int], jobs: int | None = None,
    progress: bool = False,
) -> dict[str, list[TrialResult]]:
    """Every method on each seed's run (simulated once); results per method in seed order."""
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ConfigError(f"methods: unknown {', '.join(unknown)}; known: {', '.join(METHODS)}")
    out: dict[str, list[TrialResult]] = {m: [] for m in methods}
    for per_method in _map(spec, methods, seeds, jobs, progress):
        for m, r in per_method.items():
            out[m].append(r)
    return out


def _map(spec: TrialSpec, methods: Sequence[str], seeds: Sequence[int], jobs: int | None,
         progress: bool) -> Iterator[dict[str, TrialResult]]:
    work = [(spec, tuple(methods), int(s)) for s in seeds]
    yield from parallel_map(_run_seed, work, jobs, progress, "seed")


def bar_failures(s: Summary, bars: Bars) -> list[str]:
    """Which of ``bars`` a method's summary misses (empty: all met)."""
    missed = []
    if s.failures > bars.failure_share * s.n:
        missed.append(f"failures {s.failures}/{s.n}")
    lo, hi = bars.coverage
    for i, name in enumerate(("m", "I", "lf")):
        if bars.bias_pct is not None and not abs(s.bias_pct[i]) <= bars.bias_pct:
            missed.append(f"bias {name} {s.bias_pct[i]:+.2f} %")
        if bars.std is not None and not s.std[i] <= bars.std[i]:
            missed.append(f"std {name} {s.std[i]:.3g}")
        if not lo <= s.coverage_95[i] <= hi:
            missed.append(f"coverage {name} {s.coverage_95[i]:.2f}")
        wide = bars.max_std_per_rms
        if wide is not None and not s.mean_reported_std[i] <= wide * s.rms_error[i]:
            missed.append(f"std {name} {s.mean_reported_std[i]:.3g} > {wide:g} x rms error "
                          f"{s.rms_error[i]:.3g}")
    return missed


def format_case(case: Case, results: dict[str, list[TrialResult]], fmt: str = "text") -> str:
    """A table of one case: a row per method and parameter."""
    spec = case.spec
    t = spec.truth
    head = (f"{case.label} — {spec.road}, {spec.speed_kmh:g} km/h, {spec.duration_s:g} s at "
            f"{spec.rate_hz:g} Hz; truth {t[0]:g} kg / {t[1]:g} kg m^2 / {t[2]:g} m; "
            f"{len(next(iter(results.values())))} seeds")
    cols = ("method", "parameter", "mean", "bias %", "std", "rms error", "reported std", "95 % cover",
            "failures", "model check warns", "ms")
    rows = []
    verdicts = []
    for method, rs in results.items():
        s = summarise(rs)
        for i, label in enumerate(LABELS):
            first = i == 0
            rows.append((method if first else "", label, f"{s.mean[i]:.5g}", f"{s.bias_pct[i]:+.2f}",
                         f"{s.std[i]:.3g}", f"{s.rms_error[i]:.3g}", f"{s.mean_reported_std[i]:.3g}",
                         "-" if np.isnan(s.coverage_95[i]) else f"{s.coverage_95[i] * 100:.0f} %",
                         f"{s.failures}/{s.n}" if first else "",
                         f"{s.model_warn_share * 100:.0f} %" if first and s.model_warn_share >= 0 else "",
                         f"{s.median_ms:.1f}" if first else ""))
        if case.bars is not None and method.startswith("likelihood"):
            missed = bar_failures(s, case.bars)
            verdict = "meets the case's bars" if not missed else "MISSES " + "; ".join(missed)
            verdicts.append(f"{method}: {verdict}")
    if fmt == "markdown":
        lines = [f"**{head}**", "", "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
        lines += [""] + [f"- {v}" for v in verdicts]
        return "\n".join(lines)
    widths = [max(len(c), *(len(r[j]) for r in rows)) for j, c in enumerate(cols)]
    fmt_row = "  ".join(f"{{:<{w}}}" if j < 2 else f"{{:>{w}}}" for j, w in enumerate(widths)).format
    lines = [head, "", fmt_row(*cols)] + [fmt_row(*r) for r in rows]
    return "\n".join(lines + (["", *verdicts] if verdicts else []))


def case_record(case: Case, results: dict[str, list[TrialResult]]) -> list[dict[str, object]]:
    """JSON-ready statistics of one case, one record per method."""
    out = []
    for method, rs in results.items():
        s = summarise(rs)
        rec: dict[str, object] = {"case": case.label, "method": method, "n": s.n, "failures": s.failures,
                                  "median_ms": s.median_ms, "model_warn_share": s.model_warn_share}
        for key in ("truth", "mean", "std", "bias_pct", "rms_error", "mean_reported_std", "coverage_95"):
            rec[key] = dict(zip(PARAM_NAMES, np.asarray(getattr(s, key), dtype=float).tolist(), strict=True))
        if case.bars is not None:
            rec["missed_bars"] = bar_failures(s, case.bars)
        out.append(rec)
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", choices=("half", "full"), default="half",
                   help="half (default) or full: the 7-DOF full car on two road tracks (methods likelihood "
                        "and rozyn; --suite acceptance: issue 13's cases, mismatch: the full car off its "
                        "model; --vehicle a full-car file or --vehicle-preset table5-1 / second)")
    p.add_argument("--suite", choices=SUITES,
                   help="run a named set of cases (overrides the road and sensor options)")
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS),
                   help=f"comma list of methods (default: {','.join(DEFAULT_METHODS)}; "
                        f"known: {', '.join(METHODS)})")
    add_run_options(p, TRIAL_ROADS[:2], amplitudes="gaussian")
    p.add_argument("--speed-variation", type=float, default=0.0, metavar="SHARE",
                   help="sinusoidal speed change, relative amplitude (default: 0)")
    p.add_argument("--endless-road", action="store_true",
                   help="the record is a window of an endless road, not one road period (not periodic)")
    p.add_argument("--noise", type=float, default=0.0, metavar="SHARE",
                   help="white sensor noise, share of each channel's rms (default: 0)")
    p.add_argument("--bias-mps2", type=float, nargs=2, default=(0.0, 0.0), metavar=("FRONT", "REAR"),
                   help="constant sensor bias (default: 0 0)")
    p.add_argument("--sensor-offsets-m", type=float, nargs=2, default=None, metavar=("FRONT", "REAR"),
                   help="accelerometers' offsets behind the front / rear axle (default: the vehicle's)")
    vehicle = p.add_mutually_exclusive_group()
    vehicle.add_argument("--vehicle", metavar="FILE.yaml", help="vehicle parameters (default: Table 5-1)")
    vehicle.add_argument("--vehicle-preset", choices=tuple(VEHICLE_PRESETS), default="table5-1",
                         help="a built-in vehicle: table5-1 (default) or second (heavier, longer)")
    add_departure_options(p)
    add_vehicle_error_options(p)
    p.add_argument("--seeds", default="1-100", metavar="SPEC",
                   help="seeds: 1-100, or 1,5,9-12 (default: 1-100)")
    p.add_argument("--jobs", type=int, default=None, help="parallel processes (default: all cores)")
    p.add_argument("--format", choices=("text", "markdown", "json"), default="text",
                   help="text tables, markdown tables (docs/RESULTS.md) or one JSON record per case "
                        "and method")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _base_spec(args: argparse.Namespace) -> TrialSpec:
    vehicle = load_vehicle(args.vehicle) if args.vehicle else VEHICLE_PRESETS[args.vehicle_preset]
    if args.sensor_offsets_m is not None:
        vehicle = vehicle.replace(sensor_front_offset_m=args.sensor_offsets_m[0],
                                  sensor_rear_offset_m=args.sensor_offsets_m[1])
    return TrialSpec(
        road=args.road, road_class=args.road_class, amplitudes=args.amplitudes, laplace_nu=args.laplace_nu,
        waviness=args.waviness, speed_kmh=args.speed_kmh, speed_variation=args.speed_variation,
        duration_s=args.duration_s, rate_hz=args.rate_hz, noise_fraction=args.noise,
        bias_mps2=tuple(args.bias_mps2), vehicle=vehicle, periodic=not args.endless_road,
        departures=Departures(**departure_values(args)), **vehicle_error_values(args),
    )


def run(args: argparse.Namespace) -> int:
    if args.model == "full":
        from rozyn_estimator.tools import compare_full

        args.methods_defaulted = args.methods == ",".join(DEFAULT_METHODS)
        return compare_full.run(args)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    if not methods:
        raise ConfigError(f"methods: none given; known: {', '.join(METHODS)}")
    seeds = parse_seeds(args.seeds)
    base = _base_spec(args)
    cases = suite(args.suite, base) if args.suite else [Case("as given", base)]
    progress = not args.quiet and sys.stderr.isatty()
    for k, case in enumerate(cases):
        results = compare(case.spec, methods, seeds, jobs=args.jobs, progress=progress)
        if args.format == "json":
            for rec in case_record(case, results):
                print(json.dumps(rec), flush=True)
        else:
            print(("\n" if k else "") + format_case(case, results, args.format), flush=True)
    return 0
