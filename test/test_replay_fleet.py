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

from rozyn_estimator.tools import cli, replay_plot
from rozyn_estimator.tools.replay import replay
from rozyn_estimator.tools.replay_fleet import CSV_COLUMNS, FLEET_CSV

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


def _rows(out: Path) -> dict[str, dict[str, str]]:
    with (out / FLEET_CSV).open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == CSV_COLUMNS
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


def test_plot_asked_for_without_matplotlib_is_one_clear_error(fleet, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(replay_plot, "matplotlib_available", lambda: False)
    assert cli.main(["replay", str(fleet / "drive"), "--plot", "--out", str(tmp_path / "p")]) == 1
    assert "--plot needs matplotlib" in capsys.readouterr().err
    assert cli.main(["replay", str(fleet / "drive"), "--out", str(tmp_path / "q"), "--quiet"]) == 0
    assert not (tmp_path / "q" / "estimates.png").exists()  # by default: skipped without matplotlib


def test_fleet_replay_of_the_shipped_samples_with_a_truncated_copy(tmp_path):
    """README's example: the sample bags and a truncated one -> a table, a plot each, status 1."""
    root = Path(__file__).resolve().parents[1] / "bags" / "samples"
    broken = tmp_path / "broken"
    shutil.copytree(root / "iso-a-100kmh", broken)
    data = broken / "iso-a-100kmh_0.mcap"
    data.write_bytes(data.read_bytes()[:300_000])
    done = subprocess.run([str(BIN / "rozyn"), "replay", *map(str, sorted(root.iterdir())), str(broken),
                           "--method", "rozyn", "--no-bag", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    rows = _rows(tmp_path / "out")
    samples = ("iso-a-100kmh", "laplace-nu1-100kmh")
    assert [rows[n]["status"] for n in (*samples, "broken")] == ["ok", "ok", "failed"]
    assert all((tmp_path / "out" / n / "estimates.png").is_file() for n in samples)
    assert "broken" in done.stdout and "iso-a-100kmh" in done.stdout
