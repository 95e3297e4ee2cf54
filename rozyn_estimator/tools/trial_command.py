"""``rozyn trial``: simulate seeded runs and estimate from each; a table vs truth or JSON lines.

The command's options, the :class:`~rozyn_estimator.tools.trial.TrialSpec` they describe
and the readable report (:func:`format_trials`); the trials themselves are
:mod:`rozyn_estimator.tools.trial`'s.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS
from rozyn_estimator.tools.drives import run_any_drive
from rozyn_estimator.tools.options import (
    add_departure_options,
    add_run_options,
    add_vehicle_error_options,
    add_vehicle_option,
    departure_values,
    vehicle_error_values,
)
from rozyn_estimator.tools.trial import (
    TRIAL_ROADS,
    VEHICLE_ERRORS,
    TrialResult,
    TrialSpec,
    departure_lines,
    parallel_map,
    parse_seeds,
    run_trials,
    summarise,
)
from rozyn_estimator.vehicle import Vehicle, load_vehicle
from sim_node.departures import Departures

HELP = "simulate seeded runs and estimate from each"
DESCRIPTION = ("Simulate the half car over seeded roads and run the estimator on each run; print a table "
               "vs truth, or one JSON line per trial.")
LABELS = ("mass [kg]", "pitch inertia [kg m^2]", "CoG from front axle [m]")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_run_options(p, TRIAL_ROADS, amplitudes="fixed")
    p.add_argument("--noise-std-mps2", type=float, default=0.0, help="white sensor noise (default: 0)")
    p.add_argument("--noise-fraction", type=float, default=0.0, metavar="F",
                   help="white sensor noise as a share of each channel's rms, e.g. 0.1 (default: 0)")
    p.add_argument("--method", choices=tuple(METHODS), default=None,
                   help="estimation method (default: likelihood, the nodes' default: Rozyn's pipeline "
                        "then the likelihood refinement; rozyn: Rozyn's pipeline alone; --model full has "
                        "likelihood and rozyn)")
    p.add_argument("--model", choices=("half", "full"), default="half",
                   help="half: the half car (front and rear sensors); full: the 7-DOF full car on two road "
                        "tracks, four corner sensors, estimating roll inertia and lateral CoG too "
                        "(--vehicle then takes a full-car file; default: half)")
    add_vehicle_option(p)
    add_departure_options(p)
    add_vehicle_error_options(p)
    p.add_argument("--durations-s", metavar="GRID",
                   help="a nested drive instead of --duration-s: one drive as long as the longest of these "
                        "measurement times (START:STOP:STEP and/or a comma list), estimated after each, "
                        "each update warm-started from the last; with a nested study's seed and times it "
                        "repeats that study's drive")
    seeds = p.add_mutually_exclusive_group()
    seeds.add_argument("--seed", type=int, default=1, help="one seed (default: 1)")
    seeds.add_argument("--seeds", metavar="SPEC", help="seeds: 1-100, or 1,5,9-12")
    p.add_argument("--limit", action="store_true",
                   help="with --model full: one fit to the periodogram averaged over the seeds' records, "
                        "the estimate's infinite-data limit: its departure from the truth is the model's "
                        "own bias, free of the roads' scatter, with its standard error")
    p.add_argument("--jobs", type=int, default=None, help="parallel processes (default: all cores)")
    p.add_argument("--json", action="store_true", help="one JSON object per trial per line")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def trial_spec(args: argparse.Namespace) -> TrialSpec:
    """The trial conditions the options describe."""
    return TrialSpec(
        road=args.road, road_class=args.road_class, amplitudes=args.amplitudes,
        laplace_nu=args.laplace_nu, waviness=args.waviness, speed_kmh=args.speed_kmh,
        duration_s=args.duration_s, rate_hz=args.rate_hz, noise_std_mps2=args.noise_std_mps2,
        noise_fraction=args.noise_fraction,
        vehicle=load_vehicle(args.vehicle) if args.vehicle else Vehicle(), method=args.method or "likelihood",
        departures=Departures(**departure_values(args)), **vehicle_error_values(args),
    )


def run(args: argparse.Namespace) -> int:
    """``rozyn trial``."""
    if args.limit:
        if args.model != "full" or args.durations_s is not None:
            raise ConfigError("--limit: the full car's records of one measurement time (--model full, "
                              "--duration-s)")
        from rozyn_estimator.tools import limit_full

        args.method = args.method or "likelihood"
        return limit_full.run(args)
    if args.durations_s is not None:
        return run_drives(args)
    if args.model == "full":
        from rozyn_estimator.tools import trial_full

        args.method = args.method or "likelihood"
        return trial_full.run(args)
    spec = trial_spec(args)
    seeds = parse_seeds(args.seeds if args.seeds is not None else str(args.seed))
    results = []
    for result in run_trials(spec, seeds, jobs=args.jobs, progress=not args.quiet and sys.stderr.isatty()):
        results.append(result)
        if args.json:
            print(json.dumps(result.to_dict()), flush=True)
    if not args.json:
        print(format_trials(spec, results))
    return 0


def run_drives(args: argparse.Namespace) -> int:
    """``rozyn trial --durations-s``: nested drives (:mod:`rozyn_estimator.tools.drives`), a
    report (or JSON lines, with ``duration_s``) per measurement time."""
    from rozyn_estimator.tools import trial_full
    from rozyn_estimator.tools.study.settings import parse_grid

    durations = parse_grid(args.durations_s, "durations-s")
    if args.model == "full":
        args.method = args.method or "likelihood"
    spec: TrialSpec | trial_full.FullTrialSpec = trial_full.spec_from_args(args) if args.model == "full" \
        else trial_spec(args)
    seeds = parse_seeds(args.seeds if args.seeds is not None else str(args.seed))
    warm = getattr(spec.pipeline_config(), "refine", "none") != "none"  # Rozyn's pipeline keeps no state
    drives = list(parallel_map(run_any_drive, [(spec, s, durations) for s in seeds], jobs=args.jobs,
                               progress=not args.quiet and sys.stderr.isatty(), unit="drive"))
    for j, duration in enumerate(durations):
        results = [drive[j] for drive in drives]
        if not args.json:
            print(f"nested drive: after {duration:g} s of {durations[-1]:g} s"
                  + (", warm-started from the last update" if j and warm else ""))
        if args.json:
            for result in results:
                print(json.dumps({"duration_s": duration, **result.to_dict()}), flush=True)
        elif isinstance(spec, TrialSpec):
            print(format_trials(spec.replace(duration_s=duration), results) + "\n")
        else:
            sim = dataclasses.replace(spec.sim, duration_s=duration)
            print(trial_full.format_full_trials(dataclasses.replace(spec, sim=sim), results) + "\n")
    return 0


def format_trials(spec: TrialSpec, results: Sequence[TrialResult]) -> str:
    """Readable report of trials: one estimate in detail, or a table over seeds."""
    road = {
        "iso": f"ISO 8608 class {spec.road_class.upper()} ({spec.amplitudes} amplitudes)",
        "laplace": f"Laplace road, nu = {spec.laplace_nu:g}, class {spec.road_class.upper()} "
                   f"({spec.amplitudes} amplitudes)",
        "free-decay": "free decay (flat road, initial displacement)",
    }[spec.road]
    head = (f"{road}, {spec.speed_kmh:g} km/h, {spec.duration_s:g} s at {spec.rate_hz:g} Hz, "
            f"method {spec.method}, {len(results)} seed(s)")
    lines = [head, *mismatch_lines(spec), ""]
    if len(results) == 1:
        return "\n".join(lines + _one_trial(results[0]))
    s = summarise(results)
    lines.append(f"{'parameter':<26}{'truth':>9}{'mean':>11}{'std':>10}{'bias %':>9}"
                 f"{'within 6 %':>12}{'reported std':>14}")
    for i, label in enumerate(LABELS):
        lines.append(
            f"{label:<26}{s.truth[i]:>9.4g}{s.mean[i]:>11.5g}{s.std[i]:>10.4g}{s.bias_pct[i]:>+9.2f}"
            f"{s.within_6pct[i] * 100:>11.0f}%{s.mean_reported_std[i]:>14.4g}"
        )
    lines += ["", f"failures: {s.failures} of {s.n}; median update time {s.median_ms:.1f} ms"]
    failed = [r for r in results if not r.estimate.ok]
    for r in failed[:5]:
        lines.append(f"  seed {r.seed}: {r.estimate.reason}")
    return "\n".join(lines)


def mismatch_lines(spec: TrialSpec) -> list[str]:
    """How the run departs from the estimator's model, as report lines (none: it does not)."""
    return departure_lines(spec.departures, {key: getattr(spec, key) for key in VEHICLE_ERRORS})


def _one_trial(r: TrialResult) -> list[str]:
    """The lines of one trial's estimate in detail (or why it failed)."""
    e = r.estimate
    if not e.ok or e.params is None:
        return [f"seed {r.seed}: identification failed: {e.reason}"]
    std = e.std
    lines = [f"{'parameter':<26}{'truth':>10}{'estimate':>12}{'std':>10}{'error %':>10}"]
    for i, label in enumerate(LABELS):
        s = "-" if std is None else f"{std[i]:.4g}"
        err = (e.params[i] / r.truth[i] - 1) * 100
        lines.append(f"{label:<26}{r.truth[i]:>10.4g}{e.params[i]:>12.4g}{s:>10}{err:>+10.2f}")
    modes = ", ".join(f"{m.freq_hz:.3f} Hz (damping {m.damping_ratio:.3f})" for m in e.modes)
    lines += ["", f"estimate from: {e.stage}"]
    if e.rozyn is not None and e.rozyn.ok and e.rozyn.params is not None:
        p = e.rozyn.params
        lines.append(f"Rozyn's pipeline alone: {p[0]:.4g} kg, {p[1]:.4g} kg m^2, {p[2]:.4g} m")
    lines += [f"modes (Rozyn's pipeline): {modes}", f"update time: {e.elapsed_ms:.1f} ms", *e.notes]
    return lines
