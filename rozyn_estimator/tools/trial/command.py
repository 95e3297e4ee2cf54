"""``rozyn trial``: simulate seeded runs of either car and estimate from each; a table vs truth
or JSON lines.

The command's options and the :class:`~rozyn_estimator.tools.trial.spec.TrialSpec` they
describe; the trials are :mod:`.run`'s, the nested drives :mod:`.drives`', the infinite-data
limit :mod:`.limit`'s and the readable report :mod:`.report`'s.
"""

from __future__ import annotations

import argparse
import json
import sys

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS
from rozyn_estimator.tools.cars import CARS
from rozyn_estimator.tools.options import (
    add_departure_options,
    add_run_options,
    add_speed_error_option,
    add_vehicle_error_options,
    add_vehicle_option,
    departure_values,
    vehicle_error_values,
    with_sensor_preset,
)
from rozyn_estimator.tools.trial.drives import run_drive_args
from rozyn_estimator.tools.trial.report import format_trials
from rozyn_estimator.tools.trial.run import parallel_map, parse_seeds, run_trials
from rozyn_estimator.tools.trial.spec import TRIAL_ROADS, TrialSpec
from sim_node.departures import Departures
from sim_node.sensors import MEMS_GYRO_NOISE_RADPS, MEMS_NOISE_MPS2

HELP = "simulate seeded runs and estimate from each"
DESCRIPTION = ("Simulate the half car (or with --model full the full car) over seeded roads and run the "
               "estimator on each run; print a table vs truth, or one JSON line per trial.")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_run_options(p, TRIAL_ROADS, amplitudes="fixed")
    p.add_argument("--noise-std-mps2", type=float, default=None,
                   help=f"white sensor noise [m/s²] (default: {MEMS_NOISE_MPS2:g}, a consumer MEMS "
                        "accelerometer's; 0 with --noise-fraction or a free decay; 0: exact sensors)")
    p.add_argument("--noise-fraction", type=float, default=0.0, metavar="F",
                   help="white sensor noise as a share of each channel's rms, e.g. 0.1 (default: 0)")
    p.add_argument("--gyro-noise-std-radps", type=float, default=None, metavar="RADPS",
                   help=f"white noise of a gyro channel [rad/s] (default: {MEMS_GYRO_NOISE_RADPS:g}, the "
                        "same MEMS part's gyro; 0 where the accelerometers' default is 0)")
    p.add_argument("--method", choices=tuple(METHODS), default=None,
                   help="estimation method (default: likelihood, the nodes' default: Rozyn's pipeline "
                        "then the likelihood refinement; rozyn: Rozyn's pipeline alone; --model full has "
                        "likelihood and rozyn)")
    p.add_argument("--model", choices=tuple(CARS), default="half",
                   help="half: the half car (front and rear sensors); full: the 7-DOF full car on two road "
                        "tracks, four corner sensors, estimating roll inertia and lateral CoG too "
                        "(--vehicle then takes a full-car file; default: half)")
    add_vehicle_option(p)
    add_departure_options(p)
    add_vehicle_error_options(p)
    add_speed_error_option(p)
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
    """The trial conditions the options describe (the car: ``--model``)."""
    car = CARS[args.model]
    return TrialSpec(
        road=args.road, road_class=args.road_class, amplitudes=args.amplitudes,
        laplace_nu=args.laplace_nu, waviness=args.waviness, speed_kmh=args.speed_kmh,
        drive_cycle=args.drive_cycle, duration_s=args.duration_s, rate_hz=args.rate_hz,
        noise_std_mps2=noise_std(args), gyro_noise_std_radps=gyro_noise_std(args),
        noise_fraction=args.noise_fraction,
        vehicle=with_sensor_preset(car.vehicle(args.vehicle), args.sensors),
        method=args.method or "likelihood", departures=Departures(**departure_values(args)),
        **vehicle_error_values(args), speed_error=args.speed_error, load_change_kg=args.load_change_kg,
        load_change_x_m=args.load_change_x_m, load_change_at_s=args.load_change_at_s,
    )


def noise_std(args: argparse.Namespace) -> float:
    """The absolute sensor noise: as given, else a MEMS accelerometer's (none when a relative
    noise is given instead, and none in a free decay: the thesis' check of the method)."""
    if args.noise_std_mps2 is not None:
        return float(args.noise_std_mps2)
    return 0.0 if args.noise_fraction > 0 or args.road == "free-decay" else MEMS_NOISE_MPS2


def gyro_noise_std(args: argparse.Namespace) -> float:
    """A gyro's noise: as given, else the MEMS part's where the accelerometers have theirs."""
    if args.gyro_noise_std_radps is not None:
        return float(args.gyro_noise_std_radps)
    return 0.0 if args.noise_fraction > 0 or args.road == "free-decay" else MEMS_GYRO_NOISE_RADPS


def run(args: argparse.Namespace) -> int:
    """``rozyn trial``."""
    if args.limit:
        if args.model != "full" or args.durations_s is not None:
            raise ConfigError("--limit: the full car's records of one measurement time (--model full, "
                              "--duration-s)")
        from rozyn_estimator.tools.trial import limit

        return limit.run(trial_spec(args), args)
    if args.durations_s is not None:
        return run_drives(args)
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
    """``rozyn trial --durations-s``: nested drives (:mod:`.drives`), a report (or JSON lines,
    with ``duration_s``) per measurement time."""
    from rozyn_estimator.tools.study.settings import parse_grid

    durations = parse_grid(args.durations_s, "durations-s")
    spec = trial_spec(args)
    seeds = parse_seeds(args.seeds if args.seeds is not None else str(args.seed))
    warm = spec.pipeline_config().refine != "none"  # Rozyn's pipeline keeps no state
    drives = list(parallel_map(run_drive_args, [(spec, s, durations) for s in seeds], jobs=args.jobs,
                               progress=not args.quiet and sys.stderr.isatty(), unit="drive"))
    for j, duration in enumerate(durations):
        results = [drive[j] for drive in drives]
        if args.json:
            for result in results:
                print(json.dumps({"duration_s": duration, **result.to_dict()}), flush=True)
            continue
        print(f"nested drive: after {duration:g} s of {durations[-1]:g} s"
              + (", warm-started from the last update" if j and warm else ""))
        print(format_trials(spec.replace(duration_s=duration), results) + "\n")
    return 0
