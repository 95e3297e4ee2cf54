"""``rozyn study``: the thesis' Monte-Carlo grids (chapter 5) as one command.

Every (road, speed, measurement time, trial) of a grid is one seeded trial
(:func:`rozyn_estimator.tools.trial.run_trial`; with ``--model full`` the 7-DOF full car's,
:func:`rozyn_estimator.tools.trial.run.run_trial`, five parameters), or with nested
drives (a refined method's default) every (road, speed, trial) one seeded drive, estimated
after each measurement time (:mod:`rozyn_estimator.tools.trial.drives`). Trials run in
chunks on local processes or on a Dask distributed cluster (``--scheduler``); the parent
process appends each finished chunk to ``results.csv``, so an interrupted study resumes
where it stopped. Each trial's seed is a function of the study's seed base, the cell and
the trial number only, and each trial runs on one BLAS thread: the results are
bit-identical whatever the number of workers, and a finished study's ``results.csv`` is
written in grid order. ``study.json`` records the model; a study is not continued as the
other model's.

Files in the output directory:

- ``study.json``: the settings (compared on ``--resume``) and a log of the runs;
- ``results.csv``: one row per trial (estimate, body modes, or the failure's reason);
- ``summary.csv`` / ``summary.md``: per cell mean, std, bias and failures;
- ``figures/*.png``: see :mod:`rozyn_estimator.tools.study.plots`.

This module holds the command line (options, settings from them, what is printed); the
package's other modules do the work.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS
from rozyn_estimator.tools.cars import CARS, FULL, HALF
from rozyn_estimator.tools.study.directory import (
    check_model,
    check_same_study,
    load_manifest,
    prepare_dir,
    write_manifest,
)
from rozyn_estimator.tools.study.outputs import write_outputs, write_tables
from rozyn_estimator.tools.study.results import TrialRow, read_results
from rozyn_estimator.tools.study.settings import (
    DRIVES,
    FIGURES,
    MANIFEST,
    RESULTS,
    SUMMARY_CSV,
    SUMMARY_MD,
    StudySettings,
    default_method,
    parse_grid,
    parse_roads,
)
from rozyn_estimator.tools.study.work import (
    DEFAULT_CHUNK_TRIALS,
    RunOptions,
    RunReport,
    connect_scheduler,
    run_study,
)
from rozyn_estimator.tools.trial.run import default_jobs
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle, load_any_vehicle, load_full_vehicle

HELP = "Monte-Carlo grid of the thesis: speed x measurement time x road, tables and plots"
DESCRIPTION = (
    "Run seeded trials for every road, speed and measurement time of a grid (default: the "
    "thesis' chapter 5 grid, 2 roads x 8 speeds x 12 durations x 100 trials), on local "
    "processes or a Dask cluster. Writes results.csv (one row per trial, as they finish), "
    "summary.csv/.md (mean, std, bias, failures per cell), figures/*.png and study.json "
    "into --out. An interrupted study continues with --resume. --model full studies the 7-DOF "
    "full car (four corner accelerometers: roll inertia and lateral CoG too)."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    grid = p.add_argument_group("grid (default: the thesis' chapter 5 grid)")
    grid.add_argument("--model", choices=tuple(CARS),
                      help="half: the half car (front and rear accelerometers; m, I_yy, l_f); full: the "
                           "7-DOF full car on two road tracks, four corner accelerometers (m, I_xx, I_yy, "
                           f"l_f, y_c; methods {', '.join(FULL.methods)}; --vehicle then takes a full-car "
                           "file) (default: half; on --resume: the study's)")
    grid.add_argument("--roads", metavar="LIST", help="comma list of iso, laplace (default: iso,laplace)")
    grid.add_argument("--speeds-kmh", metavar="GRID",
                      help="speeds: START:STOP:STEP and/or a comma list (default: 30:100:10)")
    grid.add_argument("--durations-s", metavar="GRID",
                      help="measurement times: START:STOP:STEP and/or a comma list (default: 10:120:10)")
    grid.add_argument("--trials", type=int, metavar="N", help="random roads per cell (default: 100)")
    grid.add_argument("--amplitudes", choices=("fixed", "gaussian"),
                      help="fixed: the thesis' road generator; gaussian: a true Gaussian road "
                           "(default: fixed)")
    grid.add_argument("--road-class", metavar="A..H", help="ISO 8608 class of the base road (default: A)")
    grid.add_argument("--laplace-nu", type=float, metavar="NU", help="Laplace road variance nu (default: 1)")
    grid.add_argument("--rate-hz", type=float, metavar="HZ", help="accelerometer rate (default: 100)")
    grid.add_argument("--noise-std-mps2", type=float, metavar="MPS2", help="white sensor noise (default: 0)")
    grid.add_argument("--noise-fraction", type=float, metavar="SHARE",
                      help="white sensor noise as a share of each channel's rms, e.g. 0.1 (default: 0)")
    grid.add_argument("--method", choices=tuple(METHODS), metavar="NAME",
                      help=f"estimation method: {', '.join(METHODS)} (default: {default_method()}, "
                           "Rozyn's pipeline without refinement; --model full: "
                           f"{', '.join(FULL.methods)}, default {FULL.default_method})")
    vehicle = grid.add_mutually_exclusive_group()
    vehicle.add_argument("--vehicle", metavar="FILE.yaml",
                         help="vehicle parameters (default: thesis Table 5-1; --model full: a file with "
                              "model: full, e.g. config/vehicle_full.yaml)")
    vehicle.add_argument("--vehicle-preset", choices=tuple(HALF.presets),
                         help="a built-in vehicle: table5-1 (the default) or second (heavier, longer; the "
                              "full car's: an SUV with its CoG 3 cm left of the centreline)")
    grid.add_argument("--seed-base", type=int, metavar="N", help="changes every road seed (default: 0)")
    grid.add_argument("--drives", choices=DRIVES,
                      help="nested: one drive per road, speed and trial, estimated after each measurement "
                           "time, each update warm-started from the last (as the node updates its growing "
                           "window); independent: a drive per cell and trial (the thesis' design) (default: "
                           "nested for a refined method, else independent)")

    run = p.add_argument_group("running")
    run.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")
    mode = run.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true",
                      help="continue the study in --out (grid options may be left out; given ones "
                           "must match)")
    mode.add_argument("--force", action="store_true", help="replace the study in --out")
    mode.add_argument("--plots-only", action="store_true",
                      help="only rebuild the tables and figures from --out's results")
    workers = run.add_mutually_exclusive_group()
    workers.add_argument("--jobs", type=int, metavar="N", help="local worker processes (default: all cores)")
    workers.add_argument("--scheduler", metavar="ADDRESS",
                         help="run on the Dask distributed cluster at ADDRESS (e.g. tcp://host:8786)")
    run.add_argument("--chunk-trials", type=int, default=DEFAULT_CHUNK_TRIALS, metavar="N",
                     help=f"trials per task (default: {DEFAULT_CHUNK_TRIALS})")
    run.add_argument("--cell", metavar="KMH,S",
                     help="speed and time of the histograms, boxplot and correlation figures "
                          "(default: the grid's nearest to 100,100, the thesis' condition)")
    run.add_argument("--no-plots", action="store_true", help="write the tables but no figures")
    run.add_argument("--quiet", action="store_true", help="no progress bar")


_GRID_ARGS = ("roads", "speeds_kmh", "durations_s", "trials", "amplitudes", "road_class", "laplace_nu",
              "rate_hz", "noise_std_mps2", "noise_fraction", "method", "seed_base", "drives")
_SETTING_ARGS = ("model", *_GRID_ARGS, "vehicle", "vehicle_preset")


def settings_from_args(args: argparse.Namespace, base: StudySettings | None = None) -> StudySettings:
    """The study's settings: ``base`` (or the defaults) with the options given on the command line.

    Raises:
        ConfigError: an invalid option, or ``--model`` other than ``base``'s (a stored study's).
    """
    parsers: dict[str, Callable[[Any], Any]] = {
        "roads": parse_roads,
        "speeds_kmh": lambda t: parse_grid(t, "speeds-kmh"),
        "durations_s": lambda t: parse_grid(t, "durations-s"),
        "road_class": lambda t: str(t).upper(),
    }
    model = getattr(args, "model", None)
    if base is not None and model is not None:
        check_model(base.model, model, args.out)
    model = model or (base.model if base is not None else "half")
    changes: dict[str, Any] = {"model": model}
    for name in _GRID_ARGS:
        value = getattr(args, name, None)
        if value is not None:
            changes[name] = parsers.get(name, lambda v: v)(value)
    vehicle = _vehicle(args, model)
    if vehicle is not None:
        changes["full_vehicle" if model == "full" else "vehicle"] = vehicle
    try:
        return dataclasses.replace(base, **changes) if base else StudySettings(**changes)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(str(exc)) from None


def _vehicle(args: argparse.Namespace, model: str) -> Vehicle | FullVehicle | None:
    """The vehicle of ``--vehicle`` or ``--vehicle-preset`` for the model (None: neither given)."""
    path, preset = getattr(args, "vehicle", None), getattr(args, "vehicle_preset", None)
    if model == "full":
        return load_full_vehicle(path) if path else FULL.presets[preset] if preset else None
    if path:
        vehicle = load_any_vehicle(path)
        if isinstance(vehicle, FullVehicle):
            raise ConfigError(f"{path}: a full-car vehicle file (model: full); study it with --model full")
        return vehicle
    return HALF.presets[preset] if preset else None


def _parse_cell(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        speed, duration = (float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--cell: expected KMH,S (e.g. 100,100), got {text!r}") from None
    if not (speed > 0 and duration > 0):
        raise ConfigError(f"--cell: speed and time must be positive, got {text!r}")
    return speed, duration


def run(args: argparse.Namespace) -> int:
    """``rozyn study``."""
    out_dir: Path = args.out
    focus = _parse_cell(args.cell)
    if args.chunk_trials < 1:
        raise ConfigError(f"--chunk-trials: must be >= 1, got {args.chunk_trials}")
    if args.jobs is not None and args.jobs < 1:
        raise ConfigError(f"--jobs: must be >= 1, got {args.jobs}")
    settings, rows = _stored_study(args) if args.plots_only else _run_grid(args)
    if len(rows) < settings.n_trials:
        print(f"rozyn study: {out_dir} holds {len(rows)} of {settings.n_trials} trials; "
              f"tables and figures cover those", file=sys.stderr)
    started = time.perf_counter()
    if args.no_plots:
        write_tables(out_dir, settings, rows)
    else:
        if not args.quiet:
            print("rozyn study: writing tables and figures", file=sys.stderr)
        write_outputs(out_dir, settings, rows, focus, 1 if args.scheduler else (args.jobs or default_jobs()))
    if not args.plots_only:
        manifest = load_manifest(out_dir)
        manifest["runs"][-1]["outputs_s"] = round(time.perf_counter() - started, 3)
        write_manifest(out_dir, manifest)
    _print_done(out_dir, settings, rows, figures=not args.no_plots)
    return 0


def _stored_study(args: argparse.Namespace) -> tuple[StudySettings, list[TrialRow]]:
    """``--plots-only``: the settings and results in --out (options given must match them)."""
    manifest = load_manifest(args.out)
    settings = StudySettings.from_dict(manifest["settings"])
    if any(getattr(args, n, None) is not None for n in _SETTING_ARGS):
        check_same_study(manifest, settings_from_args(args, settings), args.out)
    if not (args.out / RESULTS).exists():
        raise ConfigError(f"{args.out}: no {RESULTS} to plot")
    return settings, read_results(args.out / RESULTS, settings.car)


def _run_grid(args: argparse.Namespace) -> tuple[StudySettings, list[TrialRow]]:
    """A new, replaced (--force) or resumed (--resume) study in --out."""
    base = None
    if args.resume and (args.out / MANIFEST).exists():
        base = StudySettings.from_dict(load_manifest(args.out)["settings"])
    settings = settings_from_args(args, base)
    options = RunOptions(
        jobs=args.jobs or default_jobs(), scheduler=args.scheduler, chunk_trials=args.chunk_trials,
        progress=not args.quiet and sys.stderr.isatty(),
    )
    client = connect_scheduler(args.scheduler) if args.scheduler else None  # before touching --out
    try:
        done = prepare_dir(args.out, settings, resume=args.resume, force=args.force)
        rows, report = run_study(settings, args.out, options, done, client)
    finally:
        if client is not None:
            client.close()
    _print_run(report)
    return settings, rows


def _print_done(out_dir: Path, settings: StudySettings, rows: Sequence[TrialRow], figures: bool) -> None:
    failures = sum(r.status != "ok" for r in rows)
    print(f"{out_dir}: {len(rows)} trials ({failures} failed) in {len(settings.cells())} cells; "
          f"{SUMMARY_MD}, {SUMMARY_CSV}, {RESULTS}" + (f", {FIGURES}/" if figures else ""))
    errors = [r for r in rows if r.status == "error"]
    if errors:
        print(f"rozyn study: {len(errors)} trials raised an exception (status 'error' in {RESULTS}), "
              f"e.g. seed {errors[0].seed} ({errors[0].cell.label}): {errors[0].reason}", file=sys.stderr)


def _print_run(report: RunReport) -> None:
    if report.trials_run:
        rate = f"{report.trials_per_s:.0f}" if report.trials_per_s >= 10 else f"{report.trials_per_s:.2g}"
        print(f"ran {report.trials_run} trials in {report.wall_s:.1f} s ({rate} trials/s)")
    else:
        print("nothing to run: every trial is in the results already")
