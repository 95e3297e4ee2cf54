"""The full car's model-fit check (method/vehicle_fit/fitcheck.py): silent on the model's own data (also
on noise-free sensors), a WARN (a note) where the suspension departs from it."""

from __future__ import annotations

import numpy as np

from rozyn_estimator.method.likelihood.fitcheck import ALPHA
from rozyn_estimator.method.pipeline import Estimate
from rozyn_estimator.online.records import WARN, Update, layout_of, update_values
from rozyn_estimator.tools.cars import FULL
from rozyn_estimator.tools.compare.suites import suite
from rozyn_estimator.tools.trial.run import run_trial
from rozyn_estimator.tools.trial.spec import TrialSpec
from sim_node.departures import Departures

# ISO A, 100 km/h, 120 s, 10 % noise
BASE = suite("acceptance", TrialSpec(vehicle=FULL.presets["table5-1"]))[3].spec


def _estimates(spec: TrialSpec, seeds: range) -> list[Estimate]:
    out = [run_trial(spec, seed).estimate for seed in seeds]
    assert all(e.ok for e in out)
    return out


def _with(departures: Departures, noise: float = 0.1) -> TrialSpec:
    return BASE.replace(departures=departures, noise_fraction=noise)


def test_the_models_own_data_fit():
    """In the model the statistic is χ² with its degrees of freedom (k² x 8 bands less the fit's
    parameters): no warning, and its mean near the degrees of freedom."""
    fits = [e.refinement.model_fit for e in _estimates(BASE, range(1, 7))]
    assert all(f is not None and f.ok and f.p_value >= ALPHA for f in fits)
    dof = fits[0].dof
    assert 100 <= dof <= 128
    assert 0.8 < np.mean([f.statistic for f in fits]) / dof < 1.25


def test_dampers_stiffer_in_rebound_are_reported():
    for est in _estimates(_with(Departures(damper_ratio=2.0)), range(1, 4)):
        fit = est.refinement.model_fit
        assert fit is not None and not fit.ok and fit.p_value < ALPHA and fit.statistic > 2 * fit.dof
        assert any(n.startswith("model check: the full-car model does not fit") for n in est.notes)
        assert "nonlinear" in fit.verdict and "likely" not in fit.verdict


def test_the_check_reaches_the_diagnostics_and_the_json():
    est = _estimates(_with(Departures(damper_ratio=2.0)), range(1, 2))[0]
    assert est.refinement.to_dict()["model_fit"]["p"] < ALPHA
    update = Update(stamp_ns=1, level=WARN, message="m", estimate=est, window_fill=1.0, fs_hz=100.0)
    values = update_values(update, layout_of(BASE.vehicle))
    assert float(values["model_fit_p"]) < ALPHA and values["model_fit"].startswith("the full-car model")


def test_noise_free_sensors_are_checked_to_the_models_resolution():
    """Four exact sensors on a rigid body span three motions: the data have no power in the fourth
    direction and the fit's floor sits at its boundary. The check takes the floor away and the
    dither stands for the model's resolution there: computed, and it fits."""
    est = _estimates(_with(Departures(), 0.0), range(1, 3))
    for e in est:
        fit = e.refinement.model_fit
        assert fit is not None and fit.ok and fit.dithered > 0.0
        assert not any("model check" in n for n in e.notes)
