"""``rozyn replay`` of full-car bags (no DDS): the sample bag, three corners, the outputs, and
clear errors for a vehicle of the other model."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from bag_helpers import check_bag

from rozyn_estimator.bag import open_bag
from rozyn_estimator.method import METHODS
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.online import CUSTOM_DATA_KEY, EstimatorConfig
from rozyn_estimator.tools import cli
from rozyn_estimator.tools.replay import replay
from rozyn_estimator.tools.replay.plot import read_updates
from rozyn_estimator.vehicle_full import CORNERS, load_full_vehicle

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "bags" / "samples" / "full-iso-a-100kmh"
TRUTH = (1000.0, 400.0, 2000.0, 1.2, 0.0)


@pytest.fixture(scope="module")
def recorded() -> EstimatorConfig:
    assert sum(f.stat().st_size for f in SAMPLE.iterdir()) <= 2 * 2**20  # small
    counts = check_bag(SAMPLE)
    assert all(counts[f"/accel/{c}"] == 10_000 for c in CORNERS) and counts["/inertia"] == 10
    with open_bag(SAMPLE) as reader:
        return EstimatorConfig.from_json(reader.custom_data[CUSTOM_DATA_KEY])


def test_the_full_sample_bag_estimates_the_recorded_truth(recorded):
    """Rozyn's stage of the full car (fast) on the sample's recorded configuration: each estimate
    but I_xx within three of its std of the truth, and all within about twice the stage's spread
    on 60 s windows (the stage's roll inertia comes out low on road data with sensor noise, by
    up to 3 std and 55 % here; the refinement's is unbiased)."""
    assert recorded.model == "full" and recorded.full_vehicle == load_full_vehicle(ROOT / "config" /
                                                                                  "vehicle_full.yaml")
    assert recorded.online.window_s == 60.0 and recorded.speed_topic == "/sim/speed"
    result = replay(SAMPLE, recorded.replace(pipeline=METHODS["rozyn"]))
    assert result.truth == TRUTH and result.accel_messages == 40_000
    assert len(result.updates) == 19 and len(result.published) == 10  # every 5 s; from 50 s on, published
    assert sorted(result.recorded) == [u.update.stamp_ns for u in result.published]  # the node's stamps
    params = np.array([u.update.params for u in result.published])
    std = np.array([u.update.estimate.std for u in result.published])
    off = (params - TRUTH) / std
    assert np.all(np.abs(off[:, [0, 2, 3, 4]]) <= 3), off  # I_xx: biased low, bounded below
    rel = np.abs(params[:, :4] / TRUTH[:4] - 1)
    assert np.all(rel[:, [0, 2, 3]] < 0.20) and np.all(rel[:, 1] < 0.6), params
    assert np.all(np.abs(params[:, 4]) < 0.1), params


def test_replay_of_three_corners_writes_the_full_car_outputs(recorded, tmp_path, capsys):
    out = tmp_path / "out"
    code = cli.main(["replay", str(SAMPLE), "--method", "rozyn", "--rear-left-topic", "", "--no-bag", "--out",
                     str(out), "--no-plot"])
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert "(full car): 30000 accelerometer messages (/accel/front_left, /accel/front_right, " \
           "/accel/rear_right, linear_acceleration.z)" in printed
    assert "overridden: pipeline, rear_left_topic" in printed
    with (out / "updates.csv").open() as f:
        rows = list(csv.DictReader(f))
    columns = list(rows[0])
    assert columns[6:11] == list(FULL_PARAM_NAMES) and "cov_ixx_yc" in columns and "mode3_damping" in columns
    assert "glitches_front" not in columns and sum(r["published"] == "1" for r in rows) == 10
    series = read_updates(out / "updates.csv")
    assert [p for p, _, _ in series.params] == list(FULL_PARAM_NAMES) and series.modes == 3


def test_a_vehicle_of_the_other_model_is_a_clear_error(tmp_path, capsys):
    for bag, vehicle, missing in ((SAMPLE, "vehicle.yaml", "/accel/front"),
                                  (ROOT / "bags" / "samples" / "iso-a-100kmh", "vehicle_full.yaml",
                                   "/accel/front_left")):
        code = cli.main(["replay", str(bag), "--vehicle", str(ROOT / "config" / vehicle), "--no-bag",
                         "--out", str(tmp_path / vehicle)])
        err = capsys.readouterr().err
        assert code == 1 and f"no topic {missing};" in err and len(err.strip().splitlines()) == 1, err
