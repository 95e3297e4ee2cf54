"""``rozyn trial --model full``: the full car's seeded trials through the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.tools.cli import main
from rozyn_estimator.tools.trial.run import simulate
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.vehicle_full import FullVehicle


def _records(capsys) -> list[dict]:
    return [json.loads(line) for line in capsys.readouterr().out.splitlines()]


def test_json_carries_the_roll_inertia_and_lateral_cog_with_a_labelled_5x5_covariance(capsys):
    assert main(["trial", "--model", "full", "--seeds", "1-2", "--json", "--jobs", "1", "--duration-s", "90",
                 "--amplitudes", "gaussian", "--noise-fraction", "0.1"]) == 0
    records = _records(capsys)
    assert [r["seed"] for r in records] == [1, 2]
    for r in records:
        assert r["status"] == "ok", r["reason"]
        assert r["stage"] == "likelihood" and r["refinement"]["status"] == "ok"
        assert r["covariance_layout"] == list(FULL_PARAM_NAMES)
        cov = np.array(r["covariance"])
        assert cov.shape == (5, 5) and np.all(np.linalg.eigvalsh(cov) > 0)
        assert r["truth"]["roll_inertia_kgm2"] == 400.0 and r["truth"]["cog_lateral_m"] == 0.0
        for i, name in enumerate(FULL_PARAM_NAMES):  # within 5 reported std of the truth
            assert abs(r[name] - r["truth"][name]) < 5 * np.sqrt(cov[i, i]), name
        assert "sensor positions" in r["budget"]["contributors"]["cog_lateral_m"]
    assert records[0]["mass_kg"] != records[1]["mass_kg"]  # the seed picks the road


def test_a_full_car_vehicle_file_is_the_truth(tmp_path, capsys):
    path = tmp_path / "car.yaml"
    path.write_text("vehicle:\n  model: full\n  cog_lateral_m: 0.06\n  roll_inertia_kgm2: 500.0\n")
    assert main(["trial", "--model", "full", "--vehicle", str(path), "--json", "--duration-s", "90"]) == 0
    r = _records(capsys)[0]
    assert r["truth"]["cog_lateral_m"] == 0.06 and r["truth"]["roll_inertia_kgm2"] == 500.0
    assert r["status"] == "ok" and abs(r["cog_lateral_m"] - 0.06) < 0.1


def test_what_the_full_car_cannot_do_is_refused_with_a_reason(capsys):
    assert main(["trial", "--model", "full", "--method", "thesis"]) == 1
    assert "the full car has likelihood, rozyn" in capsys.readouterr().err
    assert main(["trial", "--model", "full", "--vehicle", "config/vehicle.yaml"]) == 1
    assert "half-car vehicle file" in capsys.readouterr().err
    assert main(["trial", "--model", "full", "--road", "free-decay"]) == 1
    assert "ISO 8608 or Laplace" in capsys.readouterr().err


def test_the_full_car_takes_the_departures_and_the_wrong_values(capsys):
    base = ["trial", "--model", "full", "--json", "--duration-s", "60", "--noise-fraction", "0.1"]
    assert main(base) == 0
    plain = _records(capsys)[0]
    assert main([*base, "--corner-gain-errors", "0.05", "0", "0", "0", "--damper-ratio", "1.5",
                 "--stiffness-error", "0.05"]) == 0
    moved = _records(capsys)[0]
    assert moved["status"] == "ok" and moved["truth"] == plain["truth"]
    assert moved["mass_kg"] != plain["mass_kg"]


def test_the_estimator_is_told_each_corners_value_off():
    v = FullVehicle()
    told = TrialSpec(vehicle=v, stiffness_error=0.1, unsprung_mass_error=-0.2).estimator_vehicle
    assert told.suspension_stiffness_npm == pytest.approx([24750, 24750, 44000, 44000])
    assert told.unsprung_mass_kg == pytest.approx([16, 16, 26, 26])
    assert told.suspension_damping_nspm == v.suspension_damping_nspm
    assert TrialSpec(vehicle=v).estimator_vehicle is v
    with pytest.raises(ConfigError, match="stiffness_error"):
        TrialSpec(vehicle=v, stiffness_error=-1.0)


def test_corner_gains_are_refused_for_the_half_car(capsys):
    assert main(["trial", "--corner-gain-errors", "0.01", "0", "0", "0"]) == 1
    assert "corner_gain_errors" in capsys.readouterr().err


def test_the_table_names_the_departures_and_the_model_check(capsys):
    assert main(["trial", "--model", "full", "--duration-s", "60", "--noise-fraction", "0.1",
                 "--damper-ratio", "2", "--corner-gain-errors", "0.03", "0", "0", "0",
                 "--stiffness-error", "0.05"]) == 0
    out = capsys.readouterr().out
    assert "dampers 2x stiffer in rebound" in out and "+3 / +0 / +0 / +0 % (FL/FR/RL/RR)" in out
    assert "estimator told wrong: stiffness +5 %" in out
    assert "model check: the full-car model does not fit the spectra" in out


def test_the_table_names_the_five_parameters(capsys):
    assert main(["trial", "--model", "full", "--seeds", "3-4", "--jobs", "1", "--duration-s", "90"]) == 0
    out = capsys.readouterr().out
    for label in ("roll inertia", "pitch inertia", "CoG left of centre", "failures: 0 of 2"):
        assert label in out


def test_the_sensor_noise_is_not_a_copy_of_the_right_tracks_random_part():
    """The noise has its own stream: on the right track's (3) it repeated the same normal
    draws as the track's independent part, noise correlated with the road."""
    spec = TrialSpec(vehicle=FullVehicle(), amplitudes="gaussian", duration_s=10.0)
    clean = simulate(spec, 3).accel_mps2
    noisy = simulate(spec.replace(noise_fraction=0.1), 3).accel_mps2
    noise = ((noisy - clean) / (0.1 * clean.std(axis=0))).ravel()
    for stream in range(4):  # the road's, the simulator's and the right track's streams
        draws = np.random.default_rng([3, stream]).standard_normal(noise.size)
        assert abs(np.corrcoef(noise, draws)[0, 1]) < 0.05, stream
    assert abs(noise.std() - 1.0) < 0.05
