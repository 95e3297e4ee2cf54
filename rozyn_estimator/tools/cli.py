"""``rozyn``: the command-line tools (trial, demo, bench, and the tool modules).

Errors a user can act on (bad options, files, bags) print one line to stderr and exit
with status 1; usage errors exit with 2 (argparse).

Larger tools live in their own module and are found by name (``TOOL_MODULES``): each
defines ``HELP`` (one line), ``DESCRIPTION``, ``add_arguments(parser)`` and
``run(args) -> int``.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import sys
from collections.abc import Callable, Sequence

from rozyn_estimator.errors import RozynError

Command = Callable[[argparse.Namespace], int]
TOOL_MODULES = ("replay", "study", "compare")  # rozyn_estimator.<name>


def _add_vehicle(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vehicle", metavar="FILE.yaml", help="vehicle parameters (default: thesis Table 5-1)")


def add_run_options(p: argparse.ArgumentParser, roads: Sequence[str], amplitudes: str) -> None:
    """Road, speed, duration and rate of simulated runs (``trial`` and ``compare``)."""
    p.add_argument("--road", choices=roads, default="iso", help="road model (default: iso)")
    p.add_argument("--road-class", default="A", metavar="A..H", help="ISO 8608 class (default: A)")
    p.add_argument("--amplitudes", choices=("fixed", "gaussian"), default=amplitudes,
                   help="fixed: the thesis' generator; gaussian: a true Gaussian road "
                        f"(default: {amplitudes})")
    p.add_argument("--laplace-nu", type=float, default=1.0, metavar="NU",
                   help="Laplace road: variance of the section gamma variable (default: 1.0)")
    p.add_argument("--waviness", type=float, default=2.0, metavar="W", help="ISO waviness w (default: 2)")
    p.add_argument("--speed-kmh", type=float, default=100.0, help="vehicle speed (default: 100)")
    p.add_argument("--duration-s", type=float, default=100.0, help="measurement time (default: 100)")
    p.add_argument("--rate-hz", type=float, default=100.0, help="accelerometer rate (default: 100)")


def _add_trial_options(p: argparse.ArgumentParser) -> None:
    from rozyn_estimator.method import METHODS
    from rozyn_estimator.tools.trial import TRIAL_ROADS

    add_run_options(p, TRIAL_ROADS, amplitudes="fixed")
    p.add_argument("--noise-std-mps2", type=float, default=0.0, help="white sensor noise (default: 0)")
    p.add_argument("--noise-fraction", type=float, default=0.0, metavar="F",
                   help="white sensor noise as a share of each channel's rms, e.g. 0.1 (default: 0)")
    p.add_argument("--method", choices=tuple(METHODS), default="likelihood",
                   help="estimation method (default: likelihood, the nodes' default: Rozyn's pipeline "
                        "then the likelihood refinement; rozyn: Rozyn's pipeline alone)")
    _add_vehicle(p)


def _trial_spec(args: argparse.Namespace):  # -> TrialSpec (lazy import keeps --help fast)
    from rozyn_estimator.tools.trial import TrialSpec
    from rozyn_estimator.vehicle import Vehicle, load_vehicle

    return TrialSpec(
        road=args.road, road_class=args.road_class, amplitudes=args.amplitudes,
        laplace_nu=args.laplace_nu, waviness=args.waviness, speed_kmh=args.speed_kmh,
        duration_s=args.duration_s, rate_hz=args.rate_hz, noise_std_mps2=args.noise_std_mps2,
        noise_fraction=args.noise_fraction,
        vehicle=load_vehicle(args.vehicle) if args.vehicle else Vehicle(), method=args.method,
    )


def cmd_trial(args: argparse.Namespace) -> int:
    from rozyn_estimator.tools.trial import parse_seeds, run_trials

    spec = _trial_spec(args)
    seeds = parse_seeds(args.seeds if args.seeds is not None else str(args.seed))
    results = []
    for result in run_trials(spec, seeds, jobs=args.jobs, progress=not args.quiet and sys.stderr.isatty()):
        results.append(result)
        if args.json:
            print(json.dumps(result.to_dict()), flush=True)
    if not args.json:
        print(format_trials(spec, results))
    return 0


def format_trials(spec, results) -> str:
    """Readable report of trials: one estimate in detail, or a table over seeds."""
    from rozyn_estimator.tools.trial import summarise

    road = {
        "iso": f"ISO 8608 class {spec.road_class.upper()} ({spec.amplitudes} amplitudes)",
        "laplace": f"Laplace road, nu = {spec.laplace_nu:g}, class {spec.road_class.upper()} "
                   f"({spec.amplitudes} amplitudes)",
        "free-decay": "free decay (flat road, initial displacement)",
    }[spec.road]
    head = (f"{road}, {spec.speed_kmh:g} km/h, {spec.duration_s:g} s at {spec.rate_hz:g} Hz, "
            f"method {spec.method}, {len(results)} seed(s)")
    labels = ("mass [kg]", "pitch inertia [kg m^2]", "CoG from front axle [m]")
    lines = [head, ""]
    if len(results) == 1:
        r = results[0]
        e = r.estimate
        if not e.ok:
            return "\n".join([*lines, f"seed {r.seed}: identification failed: {e.reason}"])
        std = e.std
        lines.append(f"{'parameter':<26}{'truth':>10}{'estimate':>12}{'std':>10}{'error %':>10}")
        for i, label in enumerate(labels):
            s = "-" if std is None else f"{std[i]:.4g}"
            err = (e.params[i] / r.truth[i] - 1) * 100
            lines.append(f"{label:<26}{r.truth[i]:>10.4g}{e.params[i]:>12.4g}{s:>10}{err:>+10.2f}")
        modes = ", ".join(f"{m.freq_hz:.3f} Hz (damping {m.damping_ratio:.3f})" for m in e.modes)
        lines += ["", f"estimate from: {e.stage}"]
        if e.rozyn is not None and e.rozyn.ok:
            p = e.rozyn.params
            lines.append(f"Rozyn's pipeline alone: {p[0]:.4g} kg, {p[1]:.4g} kg m^2, {p[2]:.4g} m")
        lines += [f"modes (Rozyn's pipeline): {modes}", f"update time: {e.elapsed_ms:.1f} ms", *e.notes]
        return "\n".join(lines)
    s = summarise(results)
    lines.append(f"{'parameter':<26}{'truth':>9}{'mean':>11}{'std':>10}{'bias %':>9}"
                 f"{'within 6 %':>12}{'reported std':>14}")
    for i, label in enumerate(labels):
        lines.append(
            f"{label:<26}{s.truth[i]:>9.4g}{s.mean[i]:>11.5g}{s.std[i]:>10.4g}{s.bias_pct[i]:>+9.2f}"
            f"{s.within_6pct[i] * 100:>11.0f}%{s.mean_reported_std[i]:>14.4g}"
        )
    lines += ["", f"failures: {s.failures} of {s.n}; median update time {s.median_ms:.1f} ms"]
    failed = [r for r in results if not r.estimate.ok]
    for r in failed[:5]:
        lines.append(f"  seed {r.seed}: {r.estimate.reason}")
    return "\n".join(lines)


def cmd_bench(args: argparse.Namespace) -> int:
    if args.nodes:
        from rozyn_estimator.tools.node_bench import run_node_bench

        print(json.dumps(run_node_bench(quick=args.quick), indent=2))
        return 0
    from rozyn_estimator.tools.bench import run_bench

    print(json.dumps(run_bench(repeats=args.repeats), indent=2))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rozyn",
        description="Vehicle inertial parameter estimation (Rozyn & Zhang): simulate, estimate, replay.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("trial", help="simulate seeded runs and estimate from each",
                       description="Simulate the half car over seeded roads and run the estimator on "
                                   "each run; print a table vs truth, or one JSON line per trial.")
    _add_trial_options(p)
    seeds = p.add_mutually_exclusive_group()
    seeds.add_argument("--seed", type=int, default=1, help="one seed (default: 1)")
    seeds.add_argument("--seeds", metavar="SPEC", help="seeds: 1-100, or 1,5,9-12")
    p.add_argument("--jobs", type=int, default=None, help="parallel processes (default: all cores)")
    p.add_argument("--json", action="store_true", help="one JSON object per trial per line")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_trial)

    from rozyn_estimator.tools import demo as ros_demo

    p = sub.add_parser("demo", help=ros_demo.HELP, description=ros_demo.DESCRIPTION)
    ros_demo.add_arguments(p)
    p.set_defaults(func=lambda a: ros_demo.run(a))

    p = sub.add_parser("bench", help="time the simulator and the pipeline (JSON)")
    p.add_argument("--repeats", type=int, default=20, help="timing repeats (default: 20)")
    p.add_argument("--nodes", action="store_true",
                   help="instead: the estimator node under load over DDS (about 3 minutes)")
    p.add_argument("--quick", action="store_true", help="with --nodes: shorter runs (about 1 minute)")
    p.set_defaults(func=cmd_bench)

    for name in TOOL_MODULES:
        module_name = f"rozyn_estimator.tools.{name}"
        if importlib.util.find_spec(module_name) is None:
            continue
        module = importlib.import_module(module_name)
        p = sub.add_parser(name, help=module.HELP, description=module.DESCRIPTION)
        module.add_arguments(p)
        p.set_defaults(func=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except RozynError as exc:
        print(f"rozyn {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"rozyn {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
