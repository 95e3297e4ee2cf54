"""``rozyn replay`` of several bags (local processes and a real Dask cluster) and its plot.

No DDS: the bags are written here (test_replay's stream); the Dask scheduler and worker
are ``dask`` processes on localhost.
"""

from __future__ import annotations

import csv
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from bag_helpers import check_bag
from dask_helpers import DaskProcesses
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from test_replay import CONFIG, _stream, _write

from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.tools import cli
from rozyn_estimator.tools.replay import plot as replay_plot
from rozyn_estimator.tools.replay import replay
from rozyn_estimator.tools.replay.fleet import (
    CSV_COLUMNS,
    FLEET_CSV,
    FULL_CSV_COLUMNS,
    FleetRow,
    format_table,
)

BIN = Path(sys.executable).parent


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """A directory of bags: two good ones (one in a sub-directory, with the same name), a
    truncated one, one without accelerometers; a README that is no bag."""
    store = get_typestore(Stores.ROS2_JAZZY)
    root = tmp_path_factory.mktemp("fleet")
    events = _stream(60.0)
    _write(root / "drive", store, events)
    (root / "day2").mkdir()
    _write(root / "day2" / "drive", store, events, config=CONFIG.replace(online=CONFIG.online.replace(
        window_s=30.0)))
    _write(root / "truncated", store, events)
    data = root / "truncated" / "truncated_0.mcap"
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    with Writer2(root / "chatter", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        msg = store.types["std_msgs/msg/String"](data="hello")
        w.write(conn, 1, bytes(store.serialize_cdr(msg, "std_msgs/msg/String")))
    (root / "README.md").write_text("not a bag")
    return root


def _rows(out: Path, columns: tuple[str, ...] = CSV_COLUMNS) -> dict[str, dict[str, str]]:
    with (out / FLEET_CSV).open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == columns
    return {Path(r["out_dir"]).name: r for r in rows}


def test_a_directory_of_bags_replays_in_parallel_and_a_bad_bag_fails_alone(fleet, tmp_path, capsys):
    out = tmp_path / "out"
    code = cli.main(["replay", str(fleet), str(fleet / "README.md"), "--out", str(out), "--jobs", "2"])
    printed = capsys.readouterr()
    assert code == 1 and "rozyn replay: 3 of 5 bags failed" in printed.err
    rows = _rows(out)
    assert set(rows) == {"drive", "drive-2", "truncated", "chatter", "README"}  # the same name twice
    for name, bag in (("drive", fleet / "day2" / "drive"), ("drive-2", fleet / "drive")):
        row, alone = rows[name], replay(bag)
        assert row["status"] == "ok" and int(row["published"]) == len(alone.published) > 0
        last = alone.published[-1].update
        assert [float(row[k]) for k in ("mass_kg", "pitch_inertia_kgm2", "cog_from_front_axle_m")] == list(
            last.estimate.params)
        assert float(row["mass_kg_std"]) == np.sqrt(last.covariance[0, 0])
        assert float(row["duration_s"]) == alone.duration_s > 45 and float(row["truth_mass_kg"]) == 1000.0
        assert "2 window resets" in row["warnings"]
        assert (out / name / "estimates.png").is_file() and check_bag(out / name / "estimates")
    assert float(rows["drive"]["mass_kg"]) != float(rows["drive-2"]["mass_kg"])  # each its own config
    assert "damaged" in rows["truncated"]["error"] and "--salvage" in rows["truncated"]["error"]
    assert "no topic /accel/front" in rows["chatter"]["error"]
    assert "is not a bag" in rows["README"]["error"]
    table = printed.out.splitlines()
    assert table[0].split()[:3] == ["bag", "duration", "m"] and len(table) >= 7
    assert any(line.startswith("truncated ") and " failed " in line for line in table)


def test_salvage_and_plot_options_reach_every_bag(fleet, tmp_path):
    out = tmp_path / "out"
    code = cli.main(["replay", str(fleet / "drive"), str(fleet / "truncated"), "--salvage", "--no-plot",
                     "--no-bag", "--jobs", "1", "--out", str(out), "--quiet"])
    rows = _rows(out)
    assert code == 0 and rows["truncated"]["status"] == "ok" and "salvaged" in rows["truncated"]["warnings"]
    assert not list(out.rglob("*.png")) and not list(out.rglob("estimates"))


def test_a_bad_option_fails_once_before_any_bag(fleet, tmp_path, capsys):
    assert cli.main(["replay", str(fleet), "--method", "nope", "--out", str(tmp_path / "o")]) == 1
    assert capsys.readouterr().err.startswith("rozyn replay: error: --method: must be one of")
    assert not (tmp_path / "o").exists()


@pytest.fixture
def dask_cluster(tmp_path, request):
    """A ``dask scheduler`` and one ``dask worker``, processes on localhost."""
    cluster = DaskProcesses(1, tmp_path)
    request.addfinalizer(cluster.stop)
    return cluster.start()


def test_on_a_dask_cluster_the_same_rows(fleet, tmp_path, dask_cluster):
    local, remote = tmp_path / "local", tmp_path / "dask"
    bags = [str(fleet / "drive"), str(fleet / "truncated")]
    assert cli.main(["replay", *bags, "--out", str(local), "--jobs", "1", "--quiet"]) == 1
    assert cli.main(["replay", *bags, "--out", str(remote), "--scheduler", dask_cluster, "--quiet"]) == 1
    ours, theirs = _rows(local), _rows(remote)
    assert set(ours) == set(theirs) == {"drive", "truncated"}
    for name in ours:
        for column in ("status", "published", "mass_kg", "pitch_inertia_kgm2_std", "error"):
            assert ours[name][column] == theirs[name][column], (name, column)
    assert (remote / "drive" / "estimates.png").is_file()  # the worker wrote it


# --------------------------------------------------------------------------- plot
def test_the_plot_reads_its_columns_by_name(fleet, tmp_path):
    """A CSV with its columns in another order, and more of them, gives the same figure."""
    pytest.importorskip("matplotlib")
    out = tmp_path / "one"
    assert cli.main(["replay", str(fleet / "drive"), "--out", str(out), "--quiet", "--no-bag"]) == 0
    series = replay_plot.read_updates(out / "updates.csv")
    assert series.published.sum() > 0 and np.isfinite(series.column("mode2_freq_hz")).any()
    with (out / "updates.csv").open() as f:
        rows = list(csv.DictReader(f))
    shuffled = tmp_path / "shuffled.csv"
    with shuffled.open("w", newline="") as f:
        columns = ["budget_extra", *reversed(list(rows[0]))]
        writer = csv.DictWriter(f, columns)
        writer.writeheader()
        writer.writerows({**r, "budget_extra": "1.5"} for r in rows)
    import matplotlib.image

    a = replay_plot.plot_estimates(out / "updates.csv", tmp_path / "a.png", truth=(1000.0, 2000.0, 1.2))
    b = replay_plot.plot_estimates(shuffled, tmp_path / "b.png", truth=(1000.0, 2000.0, 1.2))
    assert np.array_equal(matplotlib.image.imread(a), matplotlib.image.imread(b))
    assert "published" in replay_plot._status_counts(series)
    # a load change: the truth drawn as steps from each of its stamps
    first = int(series.stamp_s[0] * 1e9)
    steps = {first: (1000.0, 2000.0, 1.2), first + 30 * 10**9: (1150.0, 2047.0, 1.278)}
    c = replay_plot.plot_estimates(out / "updates.csv", tmp_path / "c.png", truth=steps)
    assert not np.array_equal(matplotlib.image.imread(a), matplotlib.image.imread(c))


def test_plot_asked_for_without_matplotlib_is_one_clear_error(fleet, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(replay_plot, "matplotlib_available", lambda: False)
    assert cli.main(["replay", str(fleet / "drive"), "--plot", "--out", str(tmp_path / "p")]) == 1
    assert "--plot needs matplotlib" in capsys.readouterr().err
    assert cli.main(["replay", str(fleet / "drive"), "--out", str(tmp_path / "q"), "--quiet"]) == 0
    assert not (tmp_path / "q" / "estimates.png").exists()  # by default: skipped without matplotlib


def test_fleet_replay_of_the_shipped_samples_with_a_truncated_copy(tmp_path):
    """README's example: the sample bags and a truncated one -> a table, a plot each, status 1;
    the full car's sample shows its five parameters, the half car's rows their three."""
    root = Path(__file__).resolve().parents[1] / "bags" / "samples"
    broken = tmp_path / "broken"
    shutil.copytree(root / "iso-a-100kmh", broken)
    data = broken / "iso-a-100kmh_0.mcap"
    data.write_bytes(data.read_bytes()[:300_000])
    done = subprocess.run([str(BIN / "rozyn"), "replay", *map(str, sorted(root.iterdir())), str(broken),
                           "--method", "rozyn", "--no-bag", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    rows = _rows(tmp_path / "out", FULL_CSV_COLUMNS)  # a full-car bag among them
    samples = ("full-iso-a-100kmh", "iso-a-100kmh", "laplace-nu1-100kmh")
    assert [rows[n]["status"] for n in (*samples, "broken")] == ["ok", "ok", "ok", "failed"]
    assert all((tmp_path / "out" / n / "estimates.png").is_file() for n in samples)
    assert "broken" in done.stdout and "iso-a-100kmh" in done.stdout
    with (tmp_path / "out" / "full-iso-a-100kmh" / "updates.csv").open() as f:
        last = [r for r in csv.DictReader(f) if r["published"] == "1"][-1]
    full = rows["full-iso-a-100kmh"]
    for name in FULL_PARAM_NAMES:  # the last published estimate and its std
        assert float(full[name]) == float(last[name])
        assert float(full[f"{name}_std"]) == float(last[f"{name}_std"])
    assert (full["truth_roll_inertia_kgm2"], full["truth_cog_lateral_m"]) == ("400.0", "0.0")
    for name in ("iso-a-100kmh", "broken"):  # a half car's row: no roll inertia, no lateral CoG
        assert {rows[name][k] for k in FULL_CSV_COLUMNS if "roll" in k or "lateral" in k} == {""}
    table = done.stdout.splitlines()
    assert table[0].endswith("l_f [m]      I_xx [kg m²]           y_c [m]  status      warnings")
    (line,) = [t for t in table if t.startswith("full-iso-a-100kmh ")]
    assert f"{float(full['roll_inertia_kgm2']):.1f} ± {float(full['roll_inertia_kgm2_std']):.1f}" in line
    assert f"{float(full['cog_lateral_m']):.4f} ± {float(full['cog_lateral_m_std']):.4f}" in line
    (line,) = [t for t in table if t.startswith("iso-a-100kmh ")]
    assert f"{float(rows['iso-a-100kmh']['cog_from_front_axle_m']):.4f} ± " in line
    assert " –                 –  ok " in line + " "  # no roll inertia, no lateral CoG


def test_a_half_car_fleets_table_is_as_before_and_a_full_car_adds_two_columns():
    half = FleetRow("/bags/drive", "ok", duration_s=60.0, estimate=(1001.25, 1998.5, 1.20125),
                    std=(10.0, 20.0, 0.0125), warnings="2 window resets")
    failed = FleetRow("/bags/broken", "failed", error="/bags/broken: damaged")
    assert format_table([half, failed]).splitlines() == [  # as before the full car
        "bag                           duration            m [kg]      I_yy [kg m²]           l_f [m]  "
        "status      warnings",
        "-" * 114,
        "drive                            60.0s     1001.2 ± 10.0     1998.5 ± 20.0   1.2012 ± 0.0125  "
        "ok          2 window resets",
        "broken                               –                 –                 –                 –  "
        "failed      broken: damaged",
    ]
    full = FleetRow("/bags/suv", "ok", model="full", duration_s=90.0,
                    estimate=(1800.0, 3200.0, 1.55, 650.0, 0.03), std=(1.0, 2.0, 0.001, 3.0, 0.002))
    assert format_table([half, full]).splitlines() == [
        "bag                           duration            m [kg]      I_yy [kg m²]           l_f [m]      "
        "I_xx [kg m²]           y_c [m]  status      warnings",
        "-" * 150,
        "drive                            60.0s     1001.2 ± 10.0     1998.5 ± 20.0   1.2012 ± 0.0125      "
        "           –                 –  ok          2 window resets",
        "suv                              90.0s      1800.0 ± 1.0      3200.0 ± 2.0   1.5500 ± 0.0010      "
        " 650.0 ± 3.0   0.0300 ± 0.0020  ok          ",
    ]
