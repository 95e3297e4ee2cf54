"""Estimation methods side by side on the same simulated runs, for either car.

Each seed's run is simulated once and every method estimates from the very same
samples, so differences between methods are the methods', not the roads'. Per method
and parameter: the mean, the bias against the truth (per cent; the lateral CoG in
millimetres), the spread over seeds, the rms error, the mean reported standard deviation,
how often the 95 % interval from the reported covariance covers the truth, the failures,
how often the model check warned and the median time per estimate; a case with bars says
which it misses.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tools.cars import Car
from rozyn_estimator.tools.compare.suites import Bars, Case
from rozyn_estimator.tools.trial.run import TrialResult, estimate_block, parallel_map, simulate
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.tools.trial.summary import Summary, summarise


def _run_seed(args: tuple[TrialSpec, Sequence[str], int]) -> dict[str, TrialResult]:
    spec, methods, seed = args
    block = simulate(spec, seed)
    return {m: TrialResult(seed, estimate_block(spec, block, m), spec.truth, 0.0, spec.car.name)
            for m in methods}


def compare(
    spec: TrialSpec, methods: Sequence[str], seeds: Sequence[int], jobs: int | None = None,
    progress: bool = False,
) -> dict[str, list[TrialResult]]:
    """Every method on each seed's run (simulated once); results per method in seed order.

    Raises:
        ConfigError: a method the car does not have.
    """
    unknown = [m for m in methods if m not in spec.car.methods]
    if unknown:
        raise ConfigError(f"methods: the {spec.car.title} has {', '.join(spec.car.methods)}; got "
                          f"{', '.join(unknown)}")
    out: dict[str, list[TrialResult]] = {m: [] for m in methods}
    work = [(spec, tuple(methods), int(s)) for s in seeds]
    for per_method in parallel_map(_run_seed, work, jobs, progress, "seed"):
        for m, r in per_method.items():
            out[m].append(r)
    return out


def bar_failures(s: Summary, bars: Bars, car: Car) -> list[str]:
    """Which of ``bars`` a method's summary misses (empty: all met)."""
    missed = []
    if s.failures > bars.failure_share * s.n:
        missed.append(f"failures {s.failures}/{s.n}")
    lo, hi = bars.coverage
    for i, p in enumerate(car.params):
        name = p.symbol
        if p.of_half_track:
            if bars.bias_lateral_m is not None and not abs(s.bias[i]) <= bars.bias_lateral_m:
                missed.append(f"bias {name} {s.bias[i] * 1e3:+.2f} mm")
        elif bars.bias_pct is not None and not abs(s.bias_pct[i]) <= bars.bias_pct:
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


def _bias(s: Summary, i: int, car: Car) -> str:
    return f"{s.bias[i] * 1e3:+.2f} mm" if car.params[i].of_half_track else f"{s.bias_pct[i]:+.2f} %"


def format_case(case: Case, results: dict[str, list[TrialResult]], fmt: str = "text") -> str:
    """A table of one case: a row per method and parameter, and its verdicts."""
    spec, car = case.spec, case.spec.car
    truth = " / ".join(f"{x:g} {p.unit}" for x, p in zip(spec.truth, car.params, strict=True))
    drive = f"drive cycle {spec.drive_cycle}" if spec.drive_cycle else f"{spec.speed_kmh:g} km/h"
    head = (f"{case.label} — {car.title}, {spec.road} ({spec.amplitudes}), {drive}, "
            f"{spec.duration_s:g} s at {spec.rate_hz:g} Hz, {spec.noise_fraction:.0%} noise; truth {truth}; "
            f"{len(next(iter(results.values())))} seeds")
    cols = ("method", "parameter", "mean", "bias", "std", "rms error", "reported std", "95 % cover",
            "failures", "model check warns", "ms")
    rows = []
    verdicts = []
    for method, rs in results.items():
        s = summarise(rs)
        for i, p in enumerate(car.params):
            first = i == 0
            rows.append((method if first else "", f"{p.symbol} [{p.unit}]", f"{s.mean[i]:.5g}",
                         _bias(s, i, car), f"{s.std[i]:.3g}", f"{s.rms_error[i]:.3g}",
                         f"{s.mean_reported_std[i]:.3g}",
                         "-" if np.isnan(s.coverage_95[i]) else f"{s.coverage_95[i] * 100:.0f} %",
                         f"{s.failures}/{s.n}" if first else "",
                         f"{s.model_warn_share * 100:.0f} %" if first and s.model_warn_share >= 0 else "",
                         f"{s.median_ms:.1f}" if first else ""))
        if case.bars is not None and method.startswith("likelihood"):
            missed = bar_failures(s, case.bars, car)
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
    """JSON-ready statistics of one case, one record per method (per parameter by its name; the
    full car's records say ``"model": "full"``)."""
    car = case.spec.car
    out = []
    for method, rs in results.items():
        s = summarise(rs)
        model = {"model": car.name} if car.name != "half" else {}
        rec: dict[str, object] = {"case": case.label, **model, "method": method, "n": s.n,
                                  "failures": s.failures, "median_ms": s.median_ms,
                                  "model_warn_share": s.model_warn_share}
        for key in ("truth", "mean", "std", "bias", "bias_pct", "rms_error", "mean_reported_std",
                    "coverage_95"):
            rec[key] = dict(zip(car.names, np.asarray(getattr(s, key), dtype=float).tolist(), strict=True))
        if case.bars is not None:
            rec["missed_bars"] = bar_failures(s, case.bars, car)
        out.append(rec)
    return out
