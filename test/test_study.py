"""``rozyn study``: a reduced grid end to end, resume, Dask, and the summary vs the trials."""

from __future__ import annotations

import csv
import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from dask_helpers import BIN, DaskProcesses
from study_helpers import ctrl_c_at_chunk

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PARAM_NAMES
from rozyn_estimator.tools import study
from rozyn_estimator.tools.cli import main
from rozyn_estimator.tools.study import Cell, StudySettings, parse_grid, work
from rozyn_estimator.tools.trial.run import run_trial

ROOT = Path(__file__).resolve().parents[1]
GRID = ["--roads", "iso,laplace", "--speeds-kmh", "50,100", "--durations-s", "20:40:20", "--trials", "4"]
N_TRIALS = 2 * 2 * 2 * 4
FIGURES = ("std_iso", "std_laplace", "std_lines_iso", "std_lines_laplace", "bias_iso", "bias_laplace",
           "precision_iso", "precision_laplace", "std_ratio_laplace_iso", "hist_100kmh_40s", "box_100kmh_40s",
           "acf_100kmh_40s")


def _study(out: Path, *extra: str) -> int:
    return main(["study", *GRID, "--out", str(out), "--quiet", *extra])


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """The reduced grid run at once on one process, with tables and figures."""
    out = tmp_path_factory.mktemp("study") / "reference"
    assert _study(out, "--jobs", "1") == 0
    return out


def test_outputs_exist_and_summary_matches_trials(reference):
    trials = _rows(reference / "results.csv")
    assert len(trials) == N_TRIALS
    assert [(r["road"], r["speed_kmh"], r["duration_s"], r["trial"]) for r in trials][:3] == [
        ("iso", "50", "20", "0"), ("iso", "50", "20", "1"), ("iso", "50", "20", "2")]
    assert all(r["status"] == "ok" for r in trials)
    summary = _rows(reference / "summary.csv")
    assert len(summary) == 8
    truth = np.array([1000.0, 2000.0, 1.2])
    for cell in summary:
        key = (cell["road"], cell["speed_kmh"], cell["duration_s"])
        p = np.array([[float(r[n]) for n in PARAM_NAMES] for r in trials
                      if (r["road"], r["speed_kmh"], r["duration_s"]) == key])
        assert int(cell["trials"]) == len(p) == 4 and int(cell["failures"]) == 0
        for i, name in enumerate(PARAM_NAMES):
            assert float(cell[f"{name}_mean"]) == pytest.approx(p[:, i].mean(), rel=1e-12)
            assert float(cell[f"{name}_std"]) == pytest.approx(p[:, i].std(ddof=1), rel=1e-12)
            assert float(cell[f"{name}_bias_pct"]) == pytest.approx((p[:, i].mean() / truth[i] - 1) * 100,
                                                                    rel=1e-9, abs=1e-9)
            q1, q3 = np.percentile(p[:, i], [25, 75])
            assert float(cell[f"{name}_robust_std"]) == pytest.approx((q3 - q1) / 1.349, rel=1e-12)
    assert all(r[f"{name}_std"] == r[f"{name}_std_statistical"] == "" for r in trials for name in PARAM_NAMES)
    md = (reference / "summary.md").read_text()
    # a table per parameter (4 cells per road each), then the shortest drive (2 speeds per road)
    assert md.count("\n| iso |") == 3 * 4 + 2 and md.count("\n| laplace |") == 3 * 4 + 2
    assert "| mean [kg] | std [kg] | bias [%] |\n" in md and "coverage" not in md.split("## mass")[1]
    assert "## Shortest drive for 1 % (2σ)" in md
    for name in FIGURES:
        png = reference / "figures" / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert 10_000 < png.stat().st_size < 400_000, name
    manifest = json.loads((reference / "study.json").read_text())
    assert manifest["settings"]["trials"] == 4 and manifest["settings"]["pipeline"]["variance"] == "none"
    assert manifest["runs"][-1]["status"] == "complete" and manifest["runs"][-1]["trials_run"] == N_TRIALS


def test_interrupted_study_resumes_to_identical_results(reference, tmp_path):
    out = tmp_path / "resumed"
    with ctrl_c_at_chunk(3):
        assert _study(out, "--jobs", "1", "--chunk-trials", "2", "--no-plots") == 130
    assert len(_rows(out / "results.csv")) == 4
    assert json.loads((out / "study.json").read_text())["runs"][-1]["status"] == "interrupted"
    with (out / "results.csv").open("a") as f:
        f.write("laplace,100,40,3,12")  # a line cut short by the interruption
    # The options may be left out on --resume: the manifest has them.
    assert main(["study", "--out", str(out), "--resume", "--jobs", "2", "--quiet", "--no-plots"]) == 0
    assert (out / "results.csv").read_bytes() == (reference / "results.csv").read_bytes()
    runs = json.loads((out / "study.json").read_text())["runs"]
    assert [r["status"] for r in runs] == ["interrupted", "complete"]
    assert runs[-1]["trials_run"] == N_TRIALS - 4


def test_ctrl_c_stops_workers_and_keeps_finished_trials(tmp_path):
    out = tmp_path / "signal"
    # 160 refined trials (about 10 s on 2 cores), so the signal (sent once 7 rows are written)
    # finds them running: 160 or 480 of Rozyn's alone could all end before it took effect
    grid = ["--roads", "laplace", "--speeds-kmh", "30:100:10", "--durations-s", "120", "--trials", "20",
            "--method", "likelihood"]
    cmd = [str(Path(sys.executable).parent / "rozyn"), "study", *grid, "--out", str(out), "--jobs", "2",
           "--chunk-trials", "2", "--no-plots"]
    # as a terminal starts it: SIGINT at its default (a test run from a background job inherits
    # it ignored, and Python then never raises KeyboardInterrupt)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        results = out / "results.csv"
        if results.exists() and results.read_text().count("\n") > 6:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the study ended before the signal"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    done = study.read_results(out / "results.csv")
    if proc.returncode == 0 and len(done) == 160:  # every trial had ended before the signal took effect
        pytest.skip("the study finished before the signal took effect (no interruption to check)")
    assert proc.returncode == 130, (len(done), err)
    assert "continue with --resume" in err and "Traceback" not in err
    assert 6 <= len(done) < 160
    assert json.loads((out / "study.json").read_text())["runs"][-1]["status"] == "interrupted"


@pytest.fixture
def dask_processes(tmp_path, request) -> str:
    """``dask scheduler`` and two ``dask worker`` processes on localhost; their address."""
    cluster = DaskProcesses(2, tmp_path)
    request.addfinalizer(cluster.stop)
    return cluster.start()


def test_a_dask_cluster_of_processes_gives_the_local_results(dask_processes, tmp_path):
    """The refined method (its std columns too) on two Dask workers, as ``rozyn`` processes."""
    grid = ["--roads", "iso", "--speeds-kmh", "100", "--durations-s", "20,40", "--trials", "3",
            "--method", "likelihood", "--no-plots", "--quiet"]
    local, remote = tmp_path / "local", tmp_path / "dask"
    runs = ((local, ["--jobs", "1"]), (remote, ["--scheduler", dask_processes, "--chunk-trials", "1"]))
    for out, workers in runs:
        done = subprocess.run([str(BIN / "rozyn"), "study", *grid, "--out", str(out), *workers],
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
    assert (remote / "results.csv").read_bytes() == (local / "results.csv").read_bytes()
    rows = _rows(remote / "results.csv")
    assert len(rows) == 6 and all(r["stage"] == "likelihood" and r["mass_kg_std"] for r in rows)
    assert json.loads((remote / "study.json").read_text())["runs"][-1]["workers"] == dask_processes


def test_existing_study_is_not_overwritten(reference, tmp_path, capsys):
    out = tmp_path / "copy"
    out.mkdir()
    for name in ("study.json", "results.csv"):
        (out / name).write_bytes((reference / name).read_bytes())
    assert _study(out, "--no-plots") == 1
    assert "already holds a study" in capsys.readouterr().err
    assert main(["study", *GRID[:-1], "5", "--out", str(out), "--resume", "--quiet"]) == 1
    assert "trials: 4 there, 5 asked" in capsys.readouterr().err
    assert main(["study", "--out", str(out), "--resume", "--quiet", "--no-plots"]) == 0
    assert "nothing to run" in capsys.readouterr().out
    assert _study(out, "--force", "--no-plots", "--jobs", "1") == 0
    assert (out / "results.csv").read_bytes() == (reference / "results.csv").read_bytes()


def test_plots_only_rebuilds_figures_for_another_cell(reference, tmp_path):
    out = tmp_path / "plots"
    out.mkdir()
    for name in ("study.json", "results.csv"):
        (out / name).write_bytes((reference / name).read_bytes())
    assert main(["study", "--out", str(out), "--plots-only", "--cell", "50,20", "--quiet"]) == 0
    for name in ("hist_50kmh_20s", "box_50kmh_20s", "acf_50kmh_20s", "std_iso"):
        assert (out / "figures" / f"{name}.png").exists()
    assert (out / "summary.csv").read_text() == (reference / "summary.csv").read_text()


@pytest.mark.parametrize(("args", "message"), [
    (["--speeds-kmh", "30:x"], "speeds-kmh: expected START:STOP:STEP"),
    (["--durations-s", "60:10:10"], "STOP >= START"),
    (["--roads", "iso,gravel"], "unknown road 'gravel'"),
    (["--trials", "0"], "trials: must be >= 1"),
    (["--cell", "100"], "--cell: expected KMH,S"),
])
def test_bad_options_are_one_clear_line(args, message, tmp_path, capsys):
    assert main(["study", *args, "--out", str(tmp_path / "x"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(("changes", "message"), [
    ({"roads": ()}, "roads: the grid needs at least one road"),
    ({"roads": ("iso", "gravel")}, "roads: each road must be one of iso, laplace"),
    ({"speeds_kmh": (50.0, 50.0)}, "speeds_kmh: repeated values"),
    ({"durations_s": (-10.0,)}, "durations_s: must be > 0 s"),
    ({"trials": 0}, "trials: must be >= 1"),
    ({"seed_base": -1}, "seed_base: must be >= 0"),
    ({"method": "nope"}, "method: must be one of"),
    ({"road_class": "Q"}, "road.class: must be one of A..H"),  # checked as each cell's trial
])
def test_invalid_settings_name_the_field(changes, message):
    with pytest.raises(ConfigError, match=message):
        StudySettings(**changes)


def test_parse_grid():
    assert parse_grid("30:100:10", "s") == tuple(float(v) for v in range(30, 101, 10))
    assert parse_grid("10:125:10", "s")[-1] == 120.0
    assert parse_grid("120, 10:30:10", "s") == (10.0, 20.0, 30.0, 120.0)
    assert parse_grid("0.5:1.5:0.5", "s") == (0.5, 1.0, 1.5)
    for bad in ("", "a", "1:2", "1:2:0", "-5", "10,10"):
        with pytest.raises(ConfigError):
            parse_grid(bad, "s")


def test_seeds_depend_only_on_cell_and_trial():
    small = StudySettings(speeds_kmh=(50.0,), durations_s=(20.0,), trials=3)
    large = StudySettings(speeds_kmh=(30.0, 50.0), durations_s=(20.0, 60.0), trials=5, amplitudes="gaussian")
    cell = Cell("iso", 50.0, 20.0)
    assert [small.seed(cell, t) for t in range(3)] == [large.seed(cell, t) for t in range(3)]
    seeds = {large.seed(c, t) for c in large.cells() for t in range(5)}
    assert len(seeds) == len(large.cells()) * 5
    assert StudySettings(seed_base=1).seed(cell, 0) != small.seed(cell, 0)


def test_default_method_is_the_rozyn_stage_without_covariance():
    cfg = StudySettings(trials=1).pipeline_config()
    assert cfg.variance == "none"
    assert getattr(cfg, "refine", "none") == "none"


def test_dask_is_imported_only_with_a_scheduler(tmp_path):
    args = ["study", "--roads", "iso", "--speeds-kmh", "50", "--durations-s", "10", "--trials", "2",
            "--jobs", "1", "--no-plots", "--quiet", "--out", str(tmp_path / "d")]
    code = (f"import sys; from rozyn_estimator.tools.cli import main; assert main({args!r}) == 0; "
            "assert 'distributed' not in sys.modules and 'dask' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, capture_output=True)


def test_bench_trials_per_second_is_a_rate():
    """A positive, finite number of trials per second (how fast is ``rozyn bench``'s business)."""
    rate = study.bench_trials_per_second()
    assert isinstance(rate, float) and math.isfinite(rate) and rate > 0


def test_bench_trials_per_second_of_the_refined_method_runs_the_same_mix(monkeypatch):
    chunks: list[work.Chunk] = []
    monkeypatch.setattr(work, "run_chunk", chunks.append)
    study.bench_trials_per_second()
    rozyn = list(chunks)
    chunks.clear()
    rate = study.bench_trials_per_second(method="likelihood")
    assert rate > 0 and len(rozyn) == 1 + 24  # the warm-up, then one trial per road and duration
    # the refined method as its study runs it: one nested drive per road, the same times
    assert len(chunks) == 1 + 2 and [c.cell.road for c in chunks[1:]] == ["iso", "laplace"]
    assert {c.durations_s for c in chunks} == {tuple(float(d) for d in range(10, 121, 10))}
    assert sorted((c.cell.road, c.cell.duration_s) for c in rozyn[1:]) == \
        sorted((c.cell.road, d) for c in chunks[1:] for d in c.durations_s)
    assert {(c.spec.method, c.spec.pipeline_config().refine) for c in chunks} == {("likelihood",) * 2}
    assert {(c.spec.method, c.spec.pipeline_config().refine) for c in rozyn} == {("rozyn", "none")}


def test_a_trial_that_raises_is_an_error_row_not_a_crash(monkeypatch):
    settings = StudySettings(roads=("iso",), speeds_kmh=(50.0,), durations_s=(10.0,), trials=3)
    bad_seed = settings.seed(Cell("iso", 50.0, 10.0), 1)

    def flaky(spec, seed):
        if seed == bad_seed:
            raise OverflowError("numerical result out of range")
        return run_trial(spec, seed)

    monkeypatch.setattr(work, "run_trial", flaky)  # looked up there by run_chunk
    rows = study.run_chunk(study.plan_chunks(settings, set(), 10)[0])
    assert [r.status for r in rows] == ["ok", "error", "ok"]
    assert rows[1].reason == "OverflowError: numerical result out of range" and rows[1].params is None
    (summary,) = study.summarise_cells(settings, rows)
    assert summary.n == 3 and summary.failures == 1
