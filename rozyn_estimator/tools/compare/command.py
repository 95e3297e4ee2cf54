"""``rozyn compare``: estimation methods side by side on the same seeded runs, for either car,
and the named suites of cases (:mod:`.suites`); the statistics and tables are :mod:`.compare`'s.
"""

from __future__ import annotations

import argparse
import json
import sys

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS
from rozyn_estimator.tools.cars import CARS
from rozyn_estimator.tools.compare.compare import case_record, compare, format_case
from rozyn_estimator.tools.compare.suites import SUITES, Case, suite
from rozyn_estimator.tools.options import (
    add_departure_options,
    add_run_options,
    add_speed_error_option,
    add_vehicle_error_options,
    departure_values,
    vehicle_error_values,
)
from rozyn_estimator.tools.trial.run import parse_seeds
from rozyn_estimator.tools.trial.spec import TRIAL_ROADS, TrialSpec
from sim_node.departures import Departures

HELP = "run several methods on the same seeded runs: bias, std, 95 %% coverage, failures, time"
DESCRIPTION = (
    "Simulate seeded runs once and estimate from each with several methods (default: the "
    "thesis' method, Rozyn's with eq 2-21 and eq 2-22, Rozyn + the likelihood refinement, and "
    "the likelihood on auto-spectra only; the full car's: Rozyn's and Rozyn + the refinement). "
    "Prints per method and parameter: mean, bias, spread, rms error, reported std, 95 % coverage, "
    "failures, model-check warnings and time per estimate. --suite runs a named set of cases."
)
DEFAULT_METHODS = ("thesis", "rozyn-eq2-21", "rozyn", "likelihood")
_ALL_SUITES = tuple(dict.fromkeys(s for names in SUITES.values() for s in names))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", choices=tuple(CARS), default="half",
                   help="half (default) or full: the 7-DOF full car on two road tracks (methods likelihood "
                        f"and rozyn; suites {', '.join(SUITES['full'])}; --vehicle a full-car file)")
    p.add_argument("--suite", choices=_ALL_SUITES,
                   help="run a named set of cases (overrides the road and sensor options): "
                        f"{', '.join(SUITES['half'])} (the full car: {', '.join(SUITES['full'])})")
    p.add_argument("--methods", default=None,
                   help=f"comma list of methods (default: {','.join(DEFAULT_METHODS)}, those the car has; "
                        f"known: {', '.join(METHODS)})")
    add_run_options(p, TRIAL_ROADS[:2], amplitudes="gaussian")
    p.add_argument("--speed-variation", type=float, default=0.0, metavar="SHARE",
                   help="sinusoidal speed change, relative amplitude (default: 0)")
    p.add_argument("--endless-road", action="store_true",
                   help="the record is a window of an endless road, not one road period (not periodic)")
    p.add_argument("--noise", type=float, default=0.0, metavar="SHARE",
                   help="white sensor noise, share of each channel's rms (default: 0)")
    p.add_argument("--bias-mps2", type=float, nargs=2, default=(0.0, 0.0), metavar=("FRONT", "REAR"),
                   help="constant sensor bias, the half car's (default: 0 0)")
    p.add_argument("--sensor-offsets-m", type=float, nargs=2, default=None, metavar=("FRONT", "REAR"),
                   help="the half car's accelerometers' offsets behind the front / rear axle (default: the "
                        "vehicle's)")
    vehicle = p.add_mutually_exclusive_group()
    vehicle.add_argument("--vehicle", metavar="FILE.yaml", help="vehicle parameters (default: Table 5-1)")
    vehicle.add_argument("--vehicle-preset", choices=("table5-1", "second"), default="table5-1",
                         help="a built-in vehicle: table5-1 (default) or second (heavier, longer)")
    add_departure_options(p)
    add_vehicle_error_options(p)
    add_speed_error_option(p)
    p.add_argument("--seeds", default="1-100", metavar="SPEC",
                   help="seeds: 1-100, or 1,5,9-12 (default: 1-100)")
    p.add_argument("--jobs", type=int, default=None, help="parallel processes (default: all cores)")
    p.add_argument("--format", choices=("text", "markdown", "json"), default="text",
                   help="text tables, markdown tables (docs/results.md) or one JSON record per case "
                        "and method")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def base_spec(args: argparse.Namespace) -> TrialSpec:
    """The trial the options describe (the car: ``--model``)."""
    car = CARS[args.model]
    vehicle = car.vehicle(args.vehicle, args.vehicle_preset)
    if args.sensor_offsets_m is not None:
        if car.name != "half":
            raise ConfigError("--sensor-offsets-m: the half car's sensors (the full car's are its vehicle "
                              "file's sensor_x_m, sensor_y_m)")
        vehicle = vehicle.replace(sensor_front_offset_m=args.sensor_offsets_m[0],
                                  sensor_rear_offset_m=args.sensor_offsets_m[1])
    return TrialSpec(
        road=args.road, road_class=args.road_class, amplitudes=args.amplitudes, laplace_nu=args.laplace_nu,
        waviness=args.waviness, speed_kmh=args.speed_kmh, drive_cycle=args.drive_cycle,
        speed_variation=args.speed_variation,
        duration_s=args.duration_s, rate_hz=args.rate_hz, noise_fraction=args.noise,
        bias_mps2=tuple(args.bias_mps2), vehicle=vehicle, periodic=not args.endless_road,
        departures=Departures(**departure_values(args)), **vehicle_error_values(args),
        speed_error=args.speed_error, load_change_kg=args.load_change_kg,
        load_change_x_m=args.load_change_x_m, load_change_at_s=args.load_change_at_s,
    )


def run(args: argparse.Namespace) -> int:
    base = base_spec(args)
    car = base.car
    given = DEFAULT_METHODS if args.methods is None else args.methods.split(",")
    methods = [m.strip() for m in given if m.strip()]
    if args.methods is None:
        methods = [m for m in methods if m in car.methods]
    if not methods:
        raise ConfigError(f"methods: none given; the {car.title} has {', '.join(car.methods)}")
    seeds = parse_seeds(args.seeds)
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
