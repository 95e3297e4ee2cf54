"""``rozyn trial --model full --limit``: the fit to the periodogram averaged over many records,
whose departure from the truth is the model's own bias."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.method.vehicle_fit.refine import refine
from rozyn_estimator.tools.cli import main
from rozyn_estimator.tools.trial.limit import infinite_data_limit, record_spectra
from rozyn_estimator.tools.trial.run import simulate
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.vehicle_full import FullTolerances, FullVehicle

_SEEDS = range(1, 9)


def _spec(tyre: float = 0.0) -> TrialSpec:
    exact = dataclasses.replace(FullVehicle(), tolerances=FullTolerances.none())
    return TrialSpec(vehicle=exact, amplitudes="gaussian", speed_kmh=100.0, duration_s=120.0,
                     noise_fraction=0.1, tyre_stiffness_error=tyre)


def test_the_limit_of_the_model_itself_lies_within_its_standard_errors():
    limit = infinite_data_limit(_spec(), _SEEDS, jobs=1)
    assert limit.refinement.ok, limit.refinement.reason
    z = limit.departure / limit.standard_error
    assert np.all(np.abs(z) < 3.5), z.tolist()
    # the limit's standard error is one record's std over √n: far below one record's spread
    single = refine(*_one_record(_spec(), 1))
    assert single.ok and single.covariance is not None
    assert np.allclose(limit.standard_error, np.sqrt(np.diag(single.covariance) / len(_SEEDS)), rtol=0.2)


def test_a_tyre_stiffness_the_estimator_is_told_wrong_shows_as_the_models_bias():
    limit = infinite_data_limit(_spec(tyre=0.1), _SEEDS, jobs=1)
    assert limit.refinement.ok
    z = limit.departure / limit.standard_error
    assert np.abs(z[[0, 2, 3]]).min() > 5, z.tolist()  # mass, pitch inertia, CoG: many standard errors


def test_the_given_spectra_must_be_the_windows():
    spectra, speed, sensors = record_spectra((_spec(), 1))
    short = np.zeros((spectra.n_samples // 2, 4))
    ref = refine(short, spectra.fs_hz, FullVehicle(), sensors, None, speed[: short.shape[0]],
                      spectra=spectra)
    assert ref.status == "failed" and "not this window's" in ref.reason


def test_the_cli_prints_the_limit_as_a_table_and_as_json(capsys):
    argv = ["trial", "--model", "full", "--limit", "--seeds", "1-3", "--jobs", "1", "--amplitudes",
            "gaussian", "--noise-fraction", "0.1", "--duration-s", "60", "--quiet"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "infinite-data limit" in text and "averaged over 3 seed(s)" in text and "roll inertia" in text
    assert main([*argv, "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["status"] == "ok" and record["n_records"] == 3
    assert list(record["departure"]) == list(FULL_PARAM_NAMES)
    assert all(record["standard_error"][k] > 0 for k in FULL_PARAM_NAMES)


@pytest.mark.parametrize("argv", [["--limit"], ["--limit", "--model", "full", "--durations-s", "30,60"],
                                  ["--limit", "--model", "full", "--method", "rozyn"]])
def test_what_the_limit_cannot_do_is_refused(argv, capsys):
    assert main(["trial", "--seeds", "1", "--quiet", *argv]) == 1
    assert "--limit" in capsys.readouterr().err


def _one_record(spec: TrialSpec, seed: int) -> tuple:
    block = simulate(spec, seed)
    accel, speed, channels = block.accel_mps2, block.speed_mps, block.channels
    sensors = tuple(range(4))
    assert len(channels) == 4
    return accel, spec.rate_hz, spec.estimator_vehicle, sensors, spec.truth, speed, \
        spec.pipeline_config().likelihood
