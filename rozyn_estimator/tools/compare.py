"""``rozyn compare``: estimation methods side by side on the same simulated runs.

Each seed's run is simulated once and every method estimates from the very same
samples, so differences between methods are the methods', not the roads'. Per method
and parameter it reports the mean, the bias against the truth, the spread over seeds,
the mean reported standard deviation, how often the 95 % interval from the reported
covariance covers the truth, the failures and the median time per estimate.

Suites run named sets of cases (``--suite``): ``issue6`` (the four conditions issue 6
measured Rozyn's method on), ``acceptance`` (issue 6's acceptance cases) and
``robustness`` (sensor noise, bias and position, sample rate, road waviness, a window of
an endless road, speed variation, off-nominal suspension). ``--vehicle-preset second`` swaps in a second,
clearly different vehicle.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PARAM_NAMES
from rozyn_estimator.tools.options import add_run_options
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
from rozyn_estimator.vehicle import Vehicle, load_vehicle

HELP = "run several methods on the same seeded runs: bias, std, 95 %% coverage, failures, time"
DESCRIPTION = (
    "Simulate seeded runs once and estimate from each with several methods (default: the "
    "thesis' method, Rozyn's with eq 2-21 and eq 2-22, Rozyn + the likelihood refinement, and "
    "the likelihood on auto-spectra only). Prints per method and parameter: mean, bias, spread, "
    "reported std, 95 % coverage, failures and time per estimate. --suite runs issue 6's cases."
)
DEFAULT_METHODS = ("thesis", "rozyn-eq2-21", "rozyn", "likelihood", "likelihood-auto")
LABELS = ("m [kg]", "I_yy [kg m^2]", "l_f [m]")

# A second vehicle, clearly different from Table 5-1: heavier, longer wheelbase, CoG further
# back, stiffer and more damped suspension, heavier wheels, stiffer and more damped tyres.
SECOND_VEHICLE = Vehicle(
    sprung_mass_kg=1800.0, pitch_inertia_kgm2=3200.0, cog_from_front_axle_m=1.55, wheelbase_m=3.2,
    unsprung_mass_front_kg=55.0, unsprung_mass_rear_kg=75.0,
    tyre_stiffness_front_npm=260_000.0, tyre_stiffness_rear_npm=280_000.0,
    tyre_damping_front_nspm=100.0, tyre_damping_rear_nspm=100.0,
    suspension_stiffness_front_npm=60_000.0, suspension_stiffness_rear_npm=90_000.0,
    suspension_damping_front_nspm=3800.0, suspension_damping_rear_nspm=4500.0,
)
VEHICLE_PRESETS = {"table5-1": Vehicle(), "second": SECOND_VEHICLE}


@dataclass(frozen=True)
class Bars:
    """Issue 6's acceptance bars for one case (std in the parameters' units)."""

    bias_pct: float = 1.0
    std: tuple[float, float, float] = (10.0, 25.0, 0.01)
    coverage: tuple[float, float] = (0.90, 0.98)
    failure_share: float = 0.01


@dataclass(frozen=True)
class Case:
    """One condition of a suite: a label, the trial spec and (acceptance only) its bars."""

    label: str
    spec: TrialSpec
    bars: Bars | None = None


def suite(name: str, base: TrialSpec) -> list[Case]:
    """The cases of a named suite, on ``base``'s vehicle (and methods).

    Raises:
        ConfigError: unknown suite name.
    """
    iso = base.replace(road="iso", amplitudes="gaussian", road_class="A", speed_kmh=100.0, duration_s=100.0,
                       rate_hz=100.0, waviness=2.0, noise_std_mps2=0.0, noise_fraction=0.0)
    noisy = iso.replace(noise_fraction=0.1)
    if name == "issue6":
        return [
            Case("Gaussian ISO A, 100 km/h, 100 s", iso),
            Case("+10 % white sensor noise", noisy),
            Case("ISO A, 30 km/h, 120 s", iso.replace(speed_kmh=30.0, duration_s=120.0)),
            Case("Laplace nu = 1, 100 km/h, 100 s", iso.replace(road="laplace", laplace_nu=1.0)),
        ]
    if name == "acceptance":
        bars = Bars()
        cases = [Case("ISO A, 100 km/h, 100 s, 10 % noise", noisy, bars)]
        cases += [
            Case(f"ISO A, {v:g} km/h, 120 s, 10 % noise", noisy.replace(speed_kmh=v, duration_s=120.0), bars)
            for v in (30.0, 50.0, 70.0, 100.0)
        ]
        cases += [
            Case("Laplace nu = 1, 100 km/h, 100 s, 10 % noise", noisy.replace(road="laplace"), bars),
            Case("waviness w = 2.5, 100 km/h, 100 s, 10 % noise", noisy.replace(waviness=2.5),
                 dataclasses.replace(bars, bias_pct=2.0)),
        ]
        return cases
    if name == "robustness":
        moved = noisy.vehicle.replace(sensor_front_offset_m=0.4, sensor_rear_offset_m=-0.5)
        return [
            Case("no sensor noise", iso),
            Case("10 % white sensor noise", noisy),
            Case("30 % white sensor noise", iso.replace(noise_fraction=0.3)),
            Case("sensor bias +0.2 / -0.3 m/s^2", noisy.replace(bias_mps2=(0.2, -0.3))),
            Case("sensors 0.4 m behind front, 0.5 m ahead of rear axle", noisy.replace(vehicle=moved)),
            *[Case(f"sample rate {r:g} Hz", noisy.replace(rate_hz=r)) for r in (50.0, 200.0, 400.0)],
            *[Case(f"road waviness w = {w:g}", noisy.replace(waviness=w)) for w in (1.5, 2.5, 3.0)],
            Case("window from an endless road (not periodic)", noisy.replace(periodic=False)),
            Case("speed 100 km/h +-10 % (60 s period)", noisy.replace(speed_variation=0.1)),
            *[Case(f"known stiffness {e:+.0%}", noisy.replace(stiffness_error=e)) for e in (0.1, -0.1)],
            *[Case(f"known damping {e:+.0%}", noisy.replace(damping_error=e)) for e in (0.1, -0.1)],
        ]
    raise ConfigError(f"suite: must be one of issue6, acceptance, robustness, got {name!r}")


SUITES = ("issue6", "acceptance", "robustness")


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
        if not abs(s.bias_pct[i]) <= bars.bias_pct:
            missed.append(f"bias {name} {s.bias_pct[i]:+.2f} %")
        if not s.std[i] <= bars.std[i]:
            missed.append(f"std {name} {s.std[i]:.3g}")
        if not lo <= s.coverage_95[i] <= hi:
            missed.append(f"coverage {name} {s.coverage_95[i]:.2f}")
    return missed


def format_case(case: Case, results: dict[str, list[TrialResult]], fmt: str = "text") -> str:
    """A table of one case: a row per method and parameter."""
    spec = case.spec
    t = spec.truth
    head = (f"{case.label} — {spec.road}, {spec.speed_kmh:g} km/h, {spec.duration_s:g} s at "
            f"{spec.rate_hz:g} Hz; truth {t[0]:g} kg / {t[1]:g} kg m^2 / {t[2]:g} m; "
            f"{len(next(iter(results.values())))} seeds")
    cols = ("method", "parameter", "mean", "bias %", "std", "reported std", "95 % cover", "failures", "ms")
    rows = []
    verdicts = []
    for method, rs in results.items():
        s = summarise(rs)
        for i, label in enumerate(LABELS):
            rows.append((method if i == 0 else "", label, f"{s.mean[i]:.5g}", f"{s.bias_pct[i]:+.2f}",
                         f"{s.std[i]:.3g}", f"{s.mean_reported_std[i]:.3g}",
                         "-" if np.isnan(s.coverage_95[i]) else f"{s.coverage_95[i] * 100:.0f} %",
                         f"{s.failures}/{s.n}" if i == 0 else "", f"{s.median_ms:.1f}" if i == 0 else ""))
        if case.bars is not None and method.startswith("likelihood"):
            missed = bar_failures(s, case.bars)
            verdict = "meets issue 6's bars" if not missed else "MISSES " + "; ".join(missed)
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
                                  "median_ms": s.median_ms}
        for key in ("truth", "mean", "std", "bias_pct", "mean_reported_std", "coverage_95"):
            rec[key] = dict(zip(PARAM_NAMES, np.asarray(getattr(s, key), dtype=float).tolist(), strict=True))
        if case.bars is not None:
            rec["missed_bars"] = bar_failures(s, case.bars)
        out.append(rec)
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
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
    p.add_argument("--stiffness-error", type=float, default=0.0, metavar="SHARE",
                   help="the estimator is told the suspension stiffness times (1 + SHARE) (default: 0)")
    p.add_argument("--damping-error", type=float, default=0.0, metavar="SHARE",
                   help="the estimator is told the suspension damping times (1 + SHARE) (default: 0)")
    vehicle = p.add_mutually_exclusive_group()
    vehicle.add_argument("--vehicle", metavar="FILE.yaml", help="vehicle parameters (default: Table 5-1)")
    vehicle.add_argument("--vehicle-preset", choices=tuple(VEHICLE_PRESETS), default="table5-1",
                         help="a built-in vehicle: table5-1 (default) or second (heavier, longer)")
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
        bias_mps2=tuple(args.bias_mps2), vehicle=vehicle, stiffness_error=args.stiffness_error,
        damping_error=args.damping_error, periodic=not args.endless_road,
    )


def run(args: argparse.Namespace) -> int:
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
