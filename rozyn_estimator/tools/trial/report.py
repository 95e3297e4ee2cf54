"""The readable report of ``rozyn trial``, for either car: one estimate in detail, or a table
over seeds (:func:`format_trials`), with how the run departs from the estimator's model."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.method.likelihood.fitcheck import UNSTEADY
from rozyn_estimator.tools.trial.run import TrialResult
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.tools.trial.summary import summarise
from sim_node.departures import Departures

_METHOD_LABELS = {"likelihood": "Rozyn's pipeline and the likelihood refinement", "rozyn": "Rozyn's pipeline"}


def departure_lines(d: Departures, told_errors: dict[str, float], full_car: bool = False) -> list[str]:
    """How a run departs from the estimator's model (``told_errors``: the ``*_error`` shares the
    estimator is told), as report lines (none: it does not)."""
    gains = d.corner_gains if full_car else d.gains
    gain_text = f"{d.gain_error_front * 100:+g} % front, {d.gain_error_rear * 100:+g} % rear"
    if full_car and gains is not None:
        gain_text = " / ".join(f"{(g - 1) * 100:+g}" for g in gains) + " % (FL/FR/RL/RR)"
    plant = [text for on, text in (
        (d.damper_ratio != 1.0, f"dampers {d.damper_ratio:g}x stiffer in rebound than in compression"),
        (d.spring_progression != 0.0, f"progressive springs, +{d.spring_progression * 100:g} % force at "
                                      f"{d.spring_reference_m * 1e3:g} mm"),
        (gains is not None, f"sensor gain errors {gain_text}"),
        (d.time_offset_s != 0.0, f"rear sensor{'s' if full_car else ''} {d.time_offset_s * 1e3:+g} ms late"),
        (d.lowpass_hz > 0.0, f"{d.lowpass_hz:g} Hz low-pass in every sensor"),
    ) if on]
    told = [f"{key.removesuffix('_error').replace('_', ' ')} {error * 100:+g} %"
            for key, error in told_errors.items() if error != 0.0]
    return ([f"simulated vehicle departs: {'; '.join(plant)}"] if plant else []) + \
        ([f"estimator told wrong: {'; '.join(told)}"] if told else [])


def headline(spec: TrialSpec, n_seeds: int) -> str:
    """The run's conditions in one line."""
    road = {
        "iso": f"ISO 8608 class {spec.road_class.upper()} ({spec.amplitudes} amplitudes)",
        "laplace": f"Laplace road, nu = {spec.laplace_nu:g}, class {spec.road_class.upper()} "
                   f"({spec.amplitudes} amplitudes)",
        "free-decay": "free decay (flat road, initial displacement)",
    }[spec.road]
    if spec.car.name == "full":
        road = f"full car: {road}, two tracks ({spec.sim_config(0).track_coherence} coherence)"
    method = _METHOD_LABELS.get(spec.method, f"method {spec.method}") if spec.car.name == "full" \
        else f"method {spec.method}"
    speed = f"drive cycle {spec.drive_cycle}" if spec.drive_cycle else f"{spec.speed_kmh:g} km/h"
    sensors = getattr(spec.vehicle, "sensors", None)
    where = f"; sensors: {sensors.describe()}" if sensors is not None else ""
    return (f"{road}, {speed}, {spec.duration_s:g} s at {spec.rate_hz:g} Hz, "
            f"{method}, {n_seeds} seed(s){where}")


def format_trials(spec: TrialSpec, results: Sequence[TrialResult]) -> str:
    """Readable report of trials: one estimate in detail, or a table over seeds."""
    car = spec.car
    lines = [headline(spec, len(results)),
             *departure_lines(spec.departures, spec.told_errors, full_car=car.name == "full"), ""]
    if len(results) == 1:
        return "\n".join(lines + _one_trial(spec, results[0]) + _checks(spec, results))
    s = summarise(results)
    lines.append(f"{'parameter':<26}{'truth':>9}{'mean':>11}{'std':>10}{'bias':>11}"
                 f"{'within 6 %':>12}{'reported std':>14}")
    for i, p in enumerate(car.params):
        label = f"{p.description} [{p.unit}]"
        bias = f"{s.bias[i] * 1e3:+.2f} mm" if p.of_half_track else f"{s.bias_pct[i]:+.2f} %"
        within = "-" if p.of_half_track else f"{s.within_6pct[i] * 100:.0f}%"
        lines.append(f"{label:<26}{s.truth[i]:>9.4g}{s.mean[i]:>11.5g}{s.std[i]:>10.4g}{bias:>11}"
                     f"{within:>12}{s.mean_reported_std[i]:>14.4g}")
    lines += ["", f"failures: {s.failures} of {s.n}; median update time {s.median_ms:.1f} ms"]
    lines += [f"  seed {r.seed}: {r.estimate.reason}" for r in results if not r.estimate.ok][:5]
    return "\n".join(lines + _checks(spec, results))


def _checks(spec: TrialSpec, results: Sequence[TrialResult]) -> list[str]:
    """How often the model check warned, and the refinement fell back to Rozyn's estimate."""
    ok = [r for r in results if r.estimate.ok]
    fits = [r.estimate.refinement.model_fit for r in ok if r.estimate.refinement is not None
            and r.estimate.refinement.model_fit is not None]
    lines = []
    model = f"the {spec.car.name}-car model"
    unchecked = sum(f.verdict == UNSTEADY for f in fits)
    fits = [f for f in fits if f.verdict != UNSTEADY]
    if unchecked:
        lines.append(f"model check: not computed on {unchecked} window(s) holding stops or pulling away")
    if len(fits) == 1:
        lines.append(f"model check: {model} {'fits' if fits[0].ok else 'does not fit'} the spectra "
                     f"(p = {fits[0].p_value:.2g})")
    elif fits:
        misfits = sum(not f.ok for f in fits)
        lines.append(f"model check: {model} does not fit in {misfits} of {len(fits)} "
                     f"(median p = {np.median([f.p_value for f in fits]):.2g})")
    fallbacks = sum(1 for r in ok if r.estimate.refinement is not None and r.estimate.stage == "rozyn")
    if fallbacks:
        lines.append(f"refinement failed, Rozyn's estimate published: {fallbacks} of {len(results)}")
    return lines


def _one_trial(spec: TrialSpec, r: TrialResult) -> list[str]:
    """The lines of one trial's estimate in detail (or why it failed)."""
    e = r.estimate
    if not e.ok or e.params is None:
        return [f"seed {r.seed}: identification failed: {e.reason}"]
    std = e.std
    lines = [f"{'parameter':<26}{'truth':>10}{'estimate':>12}{'std':>10}{'error':>11}"]
    for i, p in enumerate(spec.car.params):
        s = "-" if std is None else f"{std[i]:.4g}"
        err = f"{(e.params[i] - r.truth[i]) * 1e3:+.2f} mm" if p.of_half_track else \
            f"{(e.params[i] / r.truth[i] - 1) * 100:+.2f} %"
        label = f"{p.description} [{p.unit}]"
        lines.append(f"{label:<26}{r.truth[i]:>10.4g}{e.params[i]:>12.4g}{s:>10}{err:>11}")
    modes = ", ".join(f"{m.freq_hz:.3f} Hz (damping {m.damping_ratio:.3f})" for m in e.modes)
    lines += ["", f"estimate from: {e.stage}"]
    if e.rozyn is not None and e.rozyn.ok and e.rozyn.params is not None:
        values = ", ".join(f"{x:.4g} {p.unit}" for x, p in zip(e.rozyn.params, spec.car.params, strict=True))
        lines.append(f"Rozyn's pipeline alone: {values}")
    lines += [f"modes (Rozyn's pipeline): {modes}", f"update time: {e.elapsed_ms:.1f} ms", *e.notes]
    return lines
