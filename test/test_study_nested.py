"""Nested drives (``tools/trial/drives.py``): a refined study's default design — one drive per road,
speed and trial, estimated after each measurement time, each update warm-started from the
last — its seeds, its windows, resume of a drive cut short, and ``rozyn trial --durations-s``.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from study_helpers import ctrl_c_at_chunk

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import estimate
from rozyn_estimator.tools.cli import main
from rozyn_estimator.tools.study import Cell, StudySettings, work
from rozyn_estimator.tools.trial.drives import drive_lengths, run_drive
from rozyn_estimator.tools.trial.run import simulate

# Rozyn's method (fast) on nested drives: the design's bookkeeping, not the refinement's numbers
GRID = ["--roads", "iso,laplace", "--speeds-kmh", "50,100", "--durations-s", "20,40", "--trials", "3",
        "--method", "rozyn", "--drives", "nested", "--no-plots", "--quiet"]


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_a_refined_method_drives_nested_and_rozyns_pipeline_independent():
    assert StudySettings(trials=1, method="likelihood").drives == "nested"
    assert StudySettings(trials=1, model="full").drives == "nested"  # the full car's default: likelihood
    assert StudySettings(trials=1).drives == "independent"  # Rozyn's pipeline: the thesis' design
    assert StudySettings(trials=1, method="likelihood", drives="independent").nested is False
    with pytest.raises(ConfigError, match="drives"):
        StudySettings(trials=1, drives="sequential")
    # a manifest written before nested drives existed was independent, whatever its method
    stored = StudySettings(trials=1, method="likelihood", drives="independent").to_dict()
    del stored["drives"]
    assert StudySettings.from_dict(stored).drives == "independent"


def test_a_nested_drive_has_one_seed_for_all_its_measurement_times():
    s = StudySettings(speeds_kmh=(50.0, 100.0), durations_s=(20.0, 40.0), trials=3, method="likelihood")
    assert s.seed(Cell("iso", 50.0, 20.0), 1) == s.seed(Cell("iso", 50.0, 40.0), 1)
    drives = {s.seed(Cell(r, v, 20.0), t) for r in s.roads for v in s.speeds_kmh for t in range(3)}
    assert len(drives) == 2 * 2 * 3
    chunks = work.plan_chunks(s, set(), 2)
    assert [(c.cell, c.trials, c.durations_s) for c in chunks[:2]] == [
        (Cell("iso", 50.0, 40.0), (0, 1), (20.0, 40.0)), (Cell("iso", 50.0, 40.0), (2,), (20.0, 40.0))]
    assert sum(c.n_rows for c in chunks) == s.n_trials
    # a drive with one time done is run again (its next time starts from it); the others not
    done = {(c.road, c.speed_kmh, c.duration_s, t) for c in s.cells() for t in range(3)}
    done.discard(("laplace", 100.0, 40.0, 1))
    (chunk,) = work.plan_chunks(s, done, 2)
    assert (chunk.cell, chunk.trials) == (Cell("laplace", 100.0, 40.0), (1,))


def test_the_windows_are_the_drives_first_samples_each_estimate_warm_from_the_last():
    s = StudySettings(roads=("iso",), speeds_kmh=(100.0,), durations_s=(10.0, 20.0), trials=1,
                      method="likelihood", amplitudes="gaussian", noise_fraction=0.1)
    spec = s.trial_spec(s.drive_cell("iso", 100.0))
    seed = s.seed(Cell("iso", 100.0, 10.0), 0)
    first, second = run_drive(spec, seed, (20.0, 10.0))  # in ascending order of the times
    block = simulate(spec, seed)  # the drive: as long as the longest time
    assert block.accel_mps2.shape[0] == 2000
    cfg = spec.pipeline_config()
    cold = estimate(block.accel_mps2[:1000], 100.0, spec.estimator_vehicle, cfg, block.speed_mps[:1000])
    warm = estimate(block.accel_mps2, 100.0, spec.estimator_vehicle, cfg, block.speed_mps, warm_start=cold)
    for got, want in ((first, cold), (second, warm)):
        assert got.estimate.stage == "likelihood" and got.seed == seed
        np.testing.assert_array_equal(got.estimate.params, want.params)
        np.testing.assert_array_equal(got.estimate.covariance, want.covariance)
    # not the same as a cold fit of the second window: the warm start is part of the design
    cold_second = estimate(block.accel_mps2, 100.0, spec.estimator_vehicle, cfg, block.speed_mps)
    assert not np.array_equal(second.estimate.params, cold_second.params)


def test_drive_lengths_are_ascending_sample_counts():
    assert drive_lengths((40.0, 20.0, 30.5), 100.0) == [2000, 3050, 4000]
    for bad in ((), (0.0, 10.0), (float("nan"),)):
        with pytest.raises(ConfigError, match="durations"):
            drive_lengths(bad, 100.0)


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("nested") / "reference"
    assert main(["study", *GRID, "--out", str(out), "--jobs", "1"]) == 0
    return out


def test_an_interrupted_nested_study_resumes_to_identical_results(reference, tmp_path):
    out = tmp_path / "resumed"
    with ctrl_c_at_chunk(3):
        assert main(["study", *GRID, "--out", str(out), "--jobs", "1", "--chunk-trials", "1"]) == 130
    lines = (out / "results.csv").read_text().splitlines(keepends=True)
    assert len(lines) == 1 + 2 * 2  # two drives of two times each
    # the last row (a drive's second time) cut short: that drive is run again, its first row kept
    (out / "results.csv").write_text("".join(lines[:-1]) + lines[-1][:20])
    assert main(["study", "--out", str(out), "--resume", "--jobs", "2", "--quiet", "--no-plots"]) == 0
    assert (out / "results.csv").read_bytes() == (reference / "results.csv").read_bytes()
    runs = json.loads((out / "study.json").read_text())["runs"]
    assert runs[-1]["status"] == "complete" and runs[-1]["trials_run"] == 24 - 3
    assert json.loads((out / "study.json").read_text())["settings"]["drives"] == "nested"


def test_rozyn_trial_durations_s_repeats_a_nested_drive(reference, capsys):
    row = next(r for r in _rows(reference / "results.csv")
               if r["road"] == "laplace" and r["speed_kmh"] == "50")
    capsys.readouterr()
    assert main(["trial", "--road", "laplace", "--speed-kmh", "50", "--seed", row["seed"], "--durations-s",
                 "20,40", "--method", "rozyn", "--noise-std-mps2", "0", "--json", "--jobs", "1"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [line["duration_s"] for line in lines] == [20.0, 40.0]
    trial = lines[[20.0, 40.0].index(float(row["duration_s"]))]
    # the study runs Rozyn's pipeline without its jackknife, whose correlation sums add up in
    # blocks: the same estimate to rounding (a refined study's repeats exactly: test_study_uncertainty)
    assert trial["seed"] == int(row["seed"])
    assert trial["mass_kg"] == pytest.approx(float(row["mass_kg"]), rel=1e-9)


def test_rozyn_trial_durations_s_prints_a_report_per_time(capsys):
    assert main(["trial", "--durations-s", "20,30", "--seed", "2", "--method", "rozyn", "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert "nested drive: after 20 s of 30 s\n" in out and "nested drive: after 30 s of 30 s\n" in out
    assert out.count("100 km/h, 20 s at 100 Hz") == 1 and out.count("100 km/h, 30 s at 100 Hz") == 1
    assert main(["trial", "--durations-s", "20,30", "--seed", "2", "--jobs", "1"]) == 0  # the refinement's
    assert "after 30 s of 30 s, warm-started from the last update" in capsys.readouterr().out
    assert main(["trial", "--durations-s", "20,-3", "--method", "rozyn"]) == 1
    assert "durations-s: values must be positive" in capsys.readouterr().err


def test_independent_drives_stay_as_they_were():
    s = StudySettings(roads=("iso",), speeds_kmh=(50.0,), durations_s=(20.0, 40.0), trials=2)
    nested = dataclasses.replace(s, drives="nested")
    assert s.seed(Cell("iso", 50.0, 20.0), 0) != s.seed(Cell("iso", 50.0, 40.0), 0)
    assert nested.seed(Cell("iso", 50.0, 20.0), 0) == nested.seed(Cell("iso", 50.0, 40.0), 0)
    chunks = work.plan_chunks(s, set(), 5)
    assert [(c.cell.duration_s, c.durations_s, c.n_rows) for c in chunks] == [(40.0, (), 2), (20.0, (), 2)]
