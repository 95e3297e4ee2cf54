"""``rozyn study --model full``: the full car's five parameters through a tiny grid, its tables,
figures and manifest, resume, --force, --plots-only, Dask, and what it refuses.

The grids here are one road, one speed, short drives and two trials (seconds each); Rozyn's
method (``--method rozyn``, a fraction of a second per trial) where the likelihood's numbers
are not the point.
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from dask_helpers import BIN, DaskProcesses
from study_helpers import ctrl_c_at_chunk

from rozyn_estimator.method import PARAM_NAMES
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.tools.cars import FULL, HALF
from rozyn_estimator.tools.cli import main
from rozyn_estimator.tools.study import Cell, StudySettings, summarise_cells
from rozyn_estimator.tools.study.correlations import cell_correlations
from rozyn_estimator.tools.study.plots import correlation_overlay, std_heatmaps
from rozyn_estimator.tools.study.precision import meets_target
from rozyn_estimator.tools.study.results import COLUMNS, FULL_COLUMNS, TrialRow, read_results
from rozyn_estimator.tools.study.summary import summary_columns

TRUTH = np.array([1000.0, 400.0, 2000.0, 1.2, 0.0])  # Table 5-1 extended: m, I_xx, I_yy, l_f, y_c
HALF_TRACK = 0.75  # the default full car's tracks: 1.5 m
FIGURES = ("std_iso", "std_lines_iso", "bias_iso", "precision_iso", "hist_100kmh_30s", "box_100kmh_30s",
           "acf_100kmh_30s")
FAST = ["--model", "full", "--roads", "iso", "--speeds-kmh", "100", "--durations-s", "20,30", "--trials", "2",
        "--method", "rozyn"]


def _records(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def _study(out: Path, *args: str) -> int:
    return main(["study", *args, "--out", str(out), "--quiet"])


@pytest.fixture(scope="module")
def refined(tmp_path_factory) -> Path:
    """The full car's default method (likelihood) on a tiny grid, Gaussian roads with 10 % sensor
    noise (issue 13's acceptance conditions), tables and figures."""
    out = tmp_path_factory.mktemp("full") / "refined"
    assert _study(out, "--model", "full", "--roads", "iso", "--speeds-kmh", "100", "--durations-s", "30",
                  "--trials", "2", "--amplitudes", "gaussian", "--noise-fraction", "0.1", "--jobs", "1") == 0
    return out


@pytest.fixture(scope="module")
def fast(tmp_path_factory) -> Path:
    """Rozyn's stage of the full car on two drive lengths, no figures."""
    out = tmp_path_factory.mktemp("full") / "fast"
    assert _study(out, *FAST, "--jobs", "1", "--no-plots") == 0
    return out


def test_results_carry_five_parameters_their_std_and_three_modes(refined):
    rows = _records(refined / "results.csv")
    assert tuple(rows[0]) == FULL_COLUMNS and len(rows) == 2
    for r in rows:
        assert r["status"] == "ok" and r["stage"] == "likelihood", r["reason"]
        for name in FULL_PARAM_NAMES:
            assert float(r[f"{name}_std"]) > float(r[f"{name}_std_statistical"]) > 0, name
        assert 0.8 < float(r["mode1_freq_hz"]) < float(r["mode2_freq_hz"]) < float(r["mode3_freq_hz"]) < 4
    manifest = json.loads((refined / "study.json").read_text())
    settings = manifest["settings"]
    assert settings["model"] == "full" and settings["method"] == "likelihood"
    assert settings["vehicle"]["model"] == "full" and settings["vehicle"]["roll_inertia_kgm2"] == 400.0
    assert "full_vehicle" not in settings and settings["pipeline"]["refine"] == "likelihood"
    assert manifest["runs"][-1]["status"] == "complete"


def test_a_study_trial_is_rozyn_trial_with_the_cells_options(refined, capsys):
    row = _records(refined / "results.csv")[1]
    assert main(["trial", "--model", "full", "--seed", row["seed"], "--duration-s", "30", "--amplitudes",
                 "gaussian", "--noise-fraction", "0.1", "--json", "--jobs", "1"]) == 0
    trial = json.loads(capsys.readouterr().out)
    for name in FULL_PARAM_NAMES:
        assert float(row[name]) == trial[name], name


def test_the_summary_is_the_trials_statistics_for_five_parameters(refined):
    trials = _records(refined / "results.csv")
    (cell,) = _records(refined / "summary.csv")
    assert tuple(cell) == summary_columns(FULL)
    p = np.array([[float(r[n]) for n in FULL_PARAM_NAMES] for r in trials])
    std = np.array([[float(r[f"{n}_std"]) for n in FULL_PARAM_NAMES] for r in trials])
    assert (cell["trials"], cell["failures"], cell["with_std"]) == ("2", "0", "2")
    for i, name in enumerate(FULL_PARAM_NAMES):
        assert float(cell[f"{name}_mean"]) == pytest.approx(p[:, i].mean(), rel=1e-12)
        assert float(cell[f"{name}_std"]) == pytest.approx(p[:, i].std(ddof=1), rel=1e-12)
        assert float(cell[f"{name}_coverage_95"]) == np.mean(np.abs(p[:, i] - TRUTH[i]) <= 1.96 * std[:, i])
    for i, name in enumerate(FULL_PARAM_NAMES[:4]):
        bias = (p[:, i].mean() / TRUTH[i] - 1) * 100
        assert float(cell[f"{name}_bias_pct"]) == pytest.approx(bias, abs=1e-9)
    # the lateral CoG, whose truth is 0: its bias in per cent of the half track
    lateral = p[:, 4].mean() / HALF_TRACK * 100
    assert float(cell["cog_lateral_m_bias_pct"]) == pytest.approx(lateral, rel=1e-12)
    md = (refined / "summary.md").read_text()
    for title in ("## mass m [kg], truth 1000", "## roll inertia I_xx [kg m²], truth 400",
                  "## pitch inertia I_yy [kg m²], truth 2000", "## CoG position l_f [m], truth 1.2",
                  "## lateral CoG y_c [m], truth 0; bias in % of the half track (0.75 m)"):
        assert md.count(title + "\n") == 1, title
    assert md.startswith("# Study: full car") and "| bias [% of half track] |" in md
    assert md.count("\n| iso | 100 | 30 | 2 | 0 |") == 5
    assert "| road | speed [km/h] | m | I_xx | I_yy | l_f | y_c |" in md


def test_the_figures_show_five_parameters_and_four_corners(refined):
    for name in FIGURES:
        png = refined / "figures" / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert not (refined / "figures" / "std_ratio_laplace_iso.png").exists()  # one road only
    settings = StudySettings.from_dict(json.loads((refined / "study.json").read_text())["settings"])
    summaries = summarise_cells(settings, read_results(refined / "results.csv"))
    assert len([ax for ax in std_heatmaps(settings, summaries, "iso").axes if ax.get_title()]) == 5
    corr = cell_correlations(settings, Cell("iso", 100.0, 30.0), trials=[0])
    assert corr.acf.shape[2] == 4 and np.allclose(corr.acf[:, 0, :], 1.0)
    assert [ax.get_title() for ax in correlation_overlay(settings, [corr]).axes][1] == \
        "iso: front right acceleration, 1 roads"


def test_an_interrupted_full_study_resumes_to_the_same_results(fast, tmp_path):
    out = tmp_path / "resumed"
    with ctrl_c_at_chunk(2):
        assert _study(out, *FAST, "--jobs", "1", "--chunk-trials", "1", "--no-plots") == 130
    assert len(_records(out / "results.csv")) == 1
    # The model comes from study.json: --resume needs no --model.
    assert _study(out, "--resume", "--jobs", "1", "--no-plots") == 0
    assert (out / "results.csv").read_bytes() == (fast / "results.csv").read_bytes()
    assert (out / "summary.csv").read_bytes() == (fast / "summary.csv").read_bytes()
    assert [r["status"] for r in json.loads((out / "study.json").read_text())["runs"]] == \
        ["interrupted", "complete"]


def test_plots_only_and_force_keep_the_model(fast, tmp_path, capsys):
    out = tmp_path / "copy"
    shutil.copytree(fast, out)
    assert _study(out, "--plots-only", "--cell", "100,20") == 0
    assert (out / "figures" / "acf_100kmh_20s.png").exists()
    assert (out / "summary.csv").read_bytes() == (fast / "summary.csv").read_bytes()
    capsys.readouterr()
    assert _study(out, "--force", "--model", "full", "--vehicle-preset", "second", "--roads", "iso",
                  "--speeds-kmh", "100", "--durations-s", "30", "--trials", "2", "--method", "rozyn",
                  "--jobs", "1", "--no-plots") == 0
    settings = json.loads((out / "study.json").read_text())["settings"]
    assert settings["vehicle"]["sprung_mass_kg"] == 1800.0 and settings["vehicle"]["cog_lateral_m"] == 0.03
    assert "truth 1800" in (out / "summary.md").read_text()


def test_a_study_of_one_model_is_not_continued_as_the_other(fast, tmp_path, capsys):
    half = tmp_path / "half"
    assert _study(half, "--roads", "iso", "--speeds-kmh", "100", "--durations-s", "20", "--trials", "2",
                  "--jobs", "1", "--no-plots") == 0
    assert "model" not in json.loads((half / "study.json").read_text())["settings"]  # as before the full car
    assert tuple(_records(half / "results.csv")[0]) == COLUMNS
    capsys.readouterr()
    before = (half / "results.csv").read_bytes()
    assert _study(half, "--resume", "--model", "full", "--no-plots") == 1
    err = capsys.readouterr().err
    assert "holds a study of the half car (--model half), not of the full car" in err and err.count("\n") == 1
    assert (half / "results.csv").read_bytes() == before
    full = tmp_path / "full"
    shutil.copytree(fast, full)
    assert _study(full, "--resume", "--model", "half", "--no-plots") == 1
    assert "holds a study of the full car (--model full), not of the half car" in capsys.readouterr().err
    assert _study(full, "--plots-only", "--model", "half") == 1
    assert "not of the half car" in capsys.readouterr().err
    # a results file of the other model under a manifest of this one is not mixed in
    shutil.copy(half / "results.csv", full / "results.csv")
    assert _study(full, "--resume", "--no-plots") == 1
    assert "results of the half car, the study's model is full" in capsys.readouterr().err


@pytest.mark.parametrize(("argv", "message"), [
    (["--method", "thesis"], "method: the full car has likelihood, rozyn, got 'thesis'"),
    (["--vehicle", "config/vehicle.yaml"], "config/vehicle.yaml: a half-car vehicle file"),
])
def test_what_the_full_car_cannot_study_is_refused(argv, message, tmp_path, capsys):
    assert main(["study", "--model", "full", *argv, "--out", str(tmp_path / "x"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_a_full_car_file_needs_the_full_model(tmp_path, capsys):
    assert _study(tmp_path / "x", "--vehicle", "config/vehicle_full.yaml") == 1
    assert "a full-car vehicle file (model: full); study it with --model full" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_the_lateral_cog_is_measured_against_the_half_track():
    settings = StudySettings(model="full", roads=("iso",), speeds_kmh=(100.0,), durations_s=(30.0,), trials=3)
    assert settings.method == "likelihood" and settings.truth().tolist() == TRUTH.tolist()
    assert settings.reference().tolist() == [1000.0, 400.0, 2000.0, 1.2, HALF_TRACK]
    cell = Cell("iso", 100.0, 30.0)
    params = [(1001.0, 400.0, 2000.0, 1.2, 0.003), (999.0, 404.0, 2000.0, 1.2, 0.001),
              (1000.0, 400.0, 2000.0, 1.2, 0.08)]
    rows = [TrialRow(cell, k, k, "ok", p, None) for k, p in enumerate(params)]
    (s,) = summarise_cells(settings, rows)
    assert s.bias_pct[4] == pytest.approx(0.028 / HALF_TRACK * 100)  # mean 28 mm of 750 mm
    assert s.bias_pct[1] == pytest.approx(100 / 3 / 100)  # the others of the truth, as the half car's
    assert s.within_6pct.tolist() == [1.0, 1.0, 1.0, 1.0, 2 / 3]  # 80 mm > 6 % of 750 mm
    assert np.isfinite(s.bias_pct).all()
    assert meets_target(s).tolist()[4] is False  # the spread's 2σ (90 mm) is 12 % of the half track


def test_the_models_name_their_estimators_parameters():
    assert HALF.names == PARAM_NAMES and FULL.names == FULL_PARAM_NAMES
    assert StudySettings(trials=1).method == "rozyn"  # the half car's default is unchanged


def test_a_dask_cluster_runs_the_full_car_as_local_processes(fast, tmp_path):
    cluster = DaskProcesses(1, tmp_path)
    try:
        address = cluster.start()
        out = tmp_path / "dask"
        done = subprocess.run([str(BIN / "rozyn"), "study", *FAST, "--out", str(out), "--scheduler", address,
                               "--chunk-trials", "1", "--no-plots", "--quiet"],
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
    finally:
        cluster.stop()
    assert (out / "results.csv").read_bytes() == (fast / "results.csv").read_bytes()
