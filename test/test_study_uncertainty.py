"""``rozyn study`` with the refined method: the std of each trial, its coverage, the shortest drive.

A tiny grid of the likelihood method (1 road, 1 speed, 2 times, 4 trials) run once here;
the summary's numbers are recomputed from ``results.csv``, and the shortest-drive rule is
checked on made-up cells.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil

import numpy as np
import pytest

from rozyn_estimator.method import METHODS, PARAM_NAMES
from rozyn_estimator.tools.cli import main
from rozyn_estimator.tools.study import (
    Cell,
    CellSummary,
    StudySettings,
    TrialRow,
    read_results,
    shortest_drives,
)
from rozyn_estimator.tools.study.plots import precision_lines
from rozyn_estimator.tools.study.precision import meets_target, shortest_drive_markdown
from rozyn_estimator.tools.study.results import COLUMNS, LEGACY_COLUMNS, scan_results
from rozyn_estimator.tools.study.summary import summarise_cells
from rozyn_estimator.tools.trial.drives import run_drive
from rozyn_estimator.tools.trial.run import run_trial

TRUTH = np.array([1000.0, 2000.0, 1.2])
GRID = ["--roads", "iso", "--speeds-kmh", "100", "--durations-s", "20,40", "--trials", "4",
        "--method", "likelihood"]
SETTINGS = StudySettings(roads=("iso",), speeds_kmh=(100.0,), durations_s=(20.0, 40.0), trials=4,
                         method="likelihood")


def _records(path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def refined(tmp_path_factory):
    """The tiny grid with the likelihood method, tables and figures."""
    out = tmp_path_factory.mktemp("refined") / "study"
    assert main(["study", *GRID, "--out", str(out), "--jobs", "1", "--quiet"]) == 0
    return out


def test_each_row_carries_the_published_and_the_statistical_std(refined):
    records = _records(refined / "results.csv")
    assert tuple(records[0]) == COLUMNS and len(records) == 8
    assert SETTINGS.nested  # a refined method's study: one drive per trial, estimated after 20 and 40 s
    spec = SETTINGS.trial_spec(SETTINGS.drive_cell("iso", 100.0))
    for record in records[::3]:  # a few trials, repeated here
        drive = run_drive(spec, int(record["seed"]), SETTINGS.durations_s)
        est = drive[SETTINGS.durations_s.index(float(record["duration_s"]))].estimate
        assert record["stage"] == est.stage == "likelihood" and est.budget is not None
        for i, name in enumerate(PARAM_NAMES):
            assert float(record[f"{name}_std"]) == np.sqrt(est.covariance[i, i])
            assert float(record[f"{name}_std_statistical"]) == np.sqrt(est.budget.statistical[i, i])
            assert float(record[f"{name}_std_statistical"]) < float(record[f"{name}_std"])
    rows = read_results(refined / "results.csv")
    assert rows[0].std == tuple(float(records[0][f"{n}_std"]) for n in PARAM_NAMES)
    assert rows[0].std_statistical == tuple(float(records[0][f"{n}_std_statistical"]) for n in PARAM_NAMES)


def test_rozyn_trial_durations_s_repeats_a_row_of_the_refined_study(refined, capsys):
    row = _records(refined / "results.csv")[-1]
    capsys.readouterr()
    assert main(["trial", "--seed", row["seed"], "--speed-kmh", "100", "--durations-s", "20,40",
                 "--method", "likelihood", "--noise-std-mps2", "0", "--json", "--jobs", "1"]) == 0
    trial = [json.loads(line) for line in capsys.readouterr().out.splitlines()][-1]
    assert trial["duration_s"] == float(row["duration_s"]) == 40.0
    for name in PARAM_NAMES:
        assert trial[name] == float(row[name]), name


def test_the_study_runs_the_refined_method_as_shipped():
    """A refined method keeps Rozyn's jackknife in the study (it scales the refinement's
    guard): the study's estimate and covariance are the shipped estimator's; Rozyn's method
    alone runs without its covariance (the study is the spread)."""
    cfg = SETTINGS.pipeline_config()
    assert cfg == METHODS["likelihood"] and cfg.refine == "likelihood"
    rozyn_only = dataclasses.replace(SETTINGS, method="rozyn").pipeline_config()
    assert rozyn_only.variance == "none" and rozyn_only.refine == "none"
    cell = Cell("iso", 100.0, 30.0)
    spec = dataclasses.replace(SETTINGS, durations_s=(30.0,)).trial_spec(cell)
    seed = SETTINGS.seed(cell, 0)
    study, shipped = (run_trial(s, seed).estimate for s in (spec, spec.replace(pipeline=None)))
    assert study.stage == shipped.stage == "likelihood"
    np.testing.assert_array_equal(study.params, shipped.params)
    np.testing.assert_array_equal(study.covariance, shipped.covariance)


def test_summary_coverage_and_published_std_match_the_trials(refined):
    records = _records(refined / "results.csv")
    summary = _records(refined / "summary.csv")
    assert len(summary) == 2
    for cell in summary:
        mine = [r for r in records if r["duration_s"] == cell["duration_s"]]
        assert int(cell["with_std"]) == len(mine) == 4
        for i, name in enumerate(PARAM_NAMES):
            p = np.array([float(r[name]) for r in mine])
            for suffix, column in (("", f"{name}_std"), ("_statistical", f"{name}_std_statistical")):
                std = np.array([float(r[column]) for r in mine])
                covered = np.abs(p - TRUTH[i]) <= 1.96 * std
                assert float(cell[f"{name}_coverage_95{suffix}"]) == np.mean(covered)
                assert float(cell[f"{name}_reported_std{suffix}"]) == pytest.approx(np.sqrt(np.mean(std**2)))
    md = (refined / "summary.md").read_text()
    assert md.count("| coverage 95 % | statistical std [kg] | coverage 95 % (statistical) |") == 1
    assert md.count("\n| iso | 100 | 20 | 4 | 0 |") == 3 and "## Shortest drive for 1 % (2σ)" in md


def _row(trial: int, params, std=None, statistical=None, status="ok") -> TrialRow:
    cell = Cell("iso", 100.0, 20.0)
    return TrialRow(cell, trial, trial, status, params, None, "", "likelihood", std, statistical)


def test_coverage_counts_the_trials_with_a_std():
    """Coverage over the successful trials that carry a std; a failed trial counts in neither."""
    settings = dataclasses.replace(SETTINGS, durations_s=(20.0,))
    std = (10.0, 20.0, 0.01)
    rows = [
        _row(0, (1005.0, 2000.0, 1.2), std, (1.0, 20.0, 0.01)),  # m: in, statistically out
        _row(1, (1019.0, 2000.0, 1.2), std, (10.0, 20.0, 0.01)),  # m: in both
        _row(2, (1021.0, 2050.0, 1.2), std, (100.0, 20.0, 0.01)),  # m: out, statistically in; I out
        _row(3, (990.0, 2000.0, 1.2)),  # no std published: in neither coverage
        _row(4, None, status="failed"),
    ]
    (s,) = summarise_cells(settings, rows)
    assert (s.n, s.failures, s.with_std) == (5, 1, 3)
    np.testing.assert_array_equal(s.coverage_95, [2 / 3, 2 / 3, 1.0])
    np.testing.assert_array_equal(s.coverage_95_statistical, [2 / 3, 2 / 3, 1.0])
    np.testing.assert_allclose(s.reported_std, std)
    np.testing.assert_allclose(s.reported_std_statistical[0], np.sqrt((1 + 100 + 10_000) / 3))
    none = summarise_cells(settings, [dataclasses.replace(r, std=None, std_statistical=None) for r in rows])
    assert none[0].with_std == 0 and np.isnan(none[0].coverage_95).all()


def test_older_results_without_std_columns_are_read_and_resumed(refined, tmp_path):
    out = tmp_path / "old"
    out.mkdir()
    shutil.copy(refined / "study.json", out / "study.json")
    records = _records(refined / "results.csv")
    with (out / "results.csv").open("w", newline="") as f:  # as written before the std columns
        writer = csv.DictWriter(f, LEGACY_COLUMNS, extrasaction="ignore", lineterminator="\n")
        writer.writeheader()
        writer.writerows(records[:3])
    rows, clean = scan_results(out / "results.csv")
    assert not clean  # the legacy header: rewritten before rows are appended
    assert [r.std for r in rows] == [None] * 3
    assert [r.params for r in rows] == [r.params for r in read_results(refined / "results.csv")[:3]]
    assert main(["study", "--out", str(out), "--resume", "--jobs", "1", "--quiet", "--no-plots"]) == 0
    resumed = _records(out / "results.csv")
    assert tuple(resumed[0]) == COLUMNS and len(resumed) == 8
    assert [r["mass_kg_std"] == "" for r in resumed] == [True] * 3 + [False] * 5
    assert [r["mass_kg"] for r in resumed] == [r["mass_kg"] for r in records]
    assert [int(c["with_std"]) for c in _records(out / "summary.csv")] == [1, 4]


def _cell(duration_s: float, two_sigma_pct, bias_pct, n: int = 100, failures: int = 0) -> CellSummary:
    """A made-up cell: 2 std [% of the truth] and bias [%] per parameter."""
    nan = np.full(3, np.nan)
    std = np.asarray(two_sigma_pct, dtype=float) / 2 / 100 * TRUTH
    return CellSummary(Cell("iso", 100.0, duration_s), n, failures, TRUTH, TRUTH, std,
                       np.asarray(bias_pct, dtype=float), nan, nan, 0, nan, nan, nan, nan)


def test_shortest_drive_for_one_percent():
    settings = StudySettings(roads=("iso",), speeds_kmh=(100.0,), durations_s=(10.0, 20.0, 30.0, 40.0))
    cells = [
        _cell(10.0, [3.0, 0.9, 2.0], [0.0, 0.6, 0.0]),
        _cell(20.0, [0.8, 0.9, 1.0], [0.0, 0.6, 0.0]),  # m by luck; l_f: 2σ = 1 % exactly
        _cell(30.0, [1.2, 0.5, 0.9], [0.0, -0.5, 0.0]),
        _cell(40.0, [0.6, 0.4, 1.1], [0.0, 0.1, 0.0]),  # l_f misses at the longest time
    ]
    assert meets_target(cells[1]).tolist() == [True, False, True]
    assert meets_target(dataclasses.replace(cells[1], n=3, failures=2)).tolist() == [False] * 3
    (drive,) = shortest_drives(settings, cells)
    assert drive.duration_s == (40.0, 30.0, None)  # m: not 20 s, as 30 s misses
    assert shortest_drive_markdown(settings, cells)[-1] == "| iso | 100 | 40 s | 30 s | > 40 s |"
    # the CoG's target is 1 % of the true l_f too: 2σ of 11 mm passes, 13 mm does not
    lf = [_cell(40.0, [0.0, 0.0, 100 * two_sigma_m / 1.2], [0.0] * 3) for two_sigma_m in (0.011, 0.013)]
    assert [bool(meets_target(c)[2]) for c in lf] == [True, False]


def test_precision_figure_shows_coverage_only_with_a_std(refined):
    rows = read_results(refined / "results.csv")
    summaries = summarise_cells(SETTINGS, rows)
    assert len(precision_lines(SETTINGS, summaries, "iso").axes) == 6  # std and coverage, 3 parameters
    without = [dataclasses.replace(r, std=None, std_statistical=None) for r in rows]
    assert len(precision_lines(SETTINGS, summarise_cells(SETTINGS, without), "iso").axes) == 3
    png = refined / "figures" / "precision_iso.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
