"""Bags written (rozyn_estimator.bag.writer) and read (bag.reader): rosbag2 layout, interoperability."""

from __future__ import annotations

import shutil
import subprocess
import sys
import threading

import numpy as np
import pytest
import yaml
from bag_helpers import check_bag, imu_bag, imu_message, z_values
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from rozyn_estimator.bag import (
    SENSOR_QOS,
    BagWriter,
    Qos,
    QueuedBagWriter,
    open_bag,
)
from rozyn_estimator.errors import BagError

NS = 1_000_000_000
IMU = "sensor_msgs/msg/Imu"


@pytest.fixture(scope="module")
def store():
    return get_typestore(Stores.ROS2_JAZZY)




def test_written_bag_is_rosbag2_and_reads_back_everywhere(tmp_path, store):
    imu_bag(tmp_path / "run", store)
    counts = check_bag(tmp_path / "run")
    assert counts == {"/accel/front": 300, "/accel/rear": 300, "/sim/ground_truth": 1}
    info = yaml.safe_load((tmp_path / "run" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    qos = {
        t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"][0]
        for t in info["topics_with_message_count"]
    }
    assert qos["/accel/front"]["reliability"] == "best_effort" and qos["/accel/front"]["depth"] == 5
    assert qos["/sim/ground_truth"]["durability"] == "transient_local"
    assert info["custom_data"] == {"note": "made by test_bag"}
    with open_bag(tmp_path / "run") as reader:
        assert reader.custom_data == {"note": "made by test_bag"}
        assert [t.count for t in reader.topics.values()] == [300, 300, 1]
        assert reader.topic("accel/front").msgtype == IMU  # relative names: root namespace
        assert z_values(reader) == [float(k) for k in range(300)]
        order = np.concatenate([b.log_ns for b in reader.batches(["accel/front", "accel/rear"], size=77)])
        assert np.all(np.diff(order) > 0)  # bag order is receive order


def test_a_bag_is_never_overwritten(tmp_path):
    (tmp_path / "x").mkdir()
    with pytest.raises(BagError, match="exists already"):
        BagWriter(tmp_path / "x")


def test_not_a_bag(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    (tmp_path / "empty").mkdir()
    cases = {
        tmp_path / "missing": "no such file or directory",
        tmp_path / "notes.txt": "is not a bag",
        tmp_path / "empty": "is not a bag: no metadata.yaml and no .mcap",
    }
    for path, words in cases.items():
        with pytest.raises(BagError, match=words):
            open_bag(path)


def test_missing_topic_lists_the_topics_there_are(tmp_path, store):
    imu_bag(tmp_path / "run", store, n=3)
    with open_bag(tmp_path / "run") as reader, pytest.raises(BagError) as err:
        reader.topic("accel/middle")
    assert "no topic /accel/middle" in str(err.value)
    assert "/accel/front (sensor_msgs/msg/Imu, 3)" in str(err.value) and "/sim/ground_truth" in str(err.value)


def test_empty_bag(tmp_path):
    with BagWriter(tmp_path / "empty") as writer:
        writer.add_topic("/accel/front", IMU, [SENSOR_QOS])
    check_bag(tmp_path / "empty")
    with pytest.raises(BagError, match="holds no messages"):
        open_bag(tmp_path / "empty")


def test_truncated_mcap_is_named_and_salvaged(tmp_path, store):
    imu_bag(tmp_path / "run", store, n=600, chunk_size=16_000)
    file = tmp_path / "run" / "run_0.mcap"
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError) as err:
        open_bag(tmp_path / "run")
    assert str(file) in str(err.value) and "damaged" in str(err.value) and "--salvage" in str(err.value)
    with open_bag(tmp_path / "run", salvage=True) as reader:
        z = z_values(reader)
        assert reader.damage and "run_0.mcap" in reader.damage[0]
        assert reader.custom_data == {"note": "made by test_bag"}
    assert 100 < len(z) < 600 and z == [float(k) for k in range(len(z))]  # an intact prefix


def test_corrupted_chunk_is_named_and_skipped_by_salvage(tmp_path, store):
    imu_bag(tmp_path / "run", store, n=600, chunk_size=16_000)
    file = tmp_path / "run" / "run_0.mcap"
    data = bytearray(file.read_bytes())
    middle = len(data) // 3
    data[middle : middle + 64] = bytes(64)
    file.write_bytes(bytes(data))
    with open_bag(tmp_path / "run") as reader, pytest.raises(BagError) as err:
        z_values(reader)
    assert str(file) in str(err.value) and "damaged" in str(err.value)
    with open_bag(tmp_path / "run", salvage=True) as reader:
        z = z_values(reader)
        assert len(reader.damage) == 1 and "chunk at byte" in reader.damage[0]
    assert 300 < len(z) < 600 and z[-1] == 599.0  # one chunk lost, the rest read to the end
    assert set(z) <= {float(k) for k in range(600)} and z == sorted(z)


def test_a_crashed_recording_loses_only_what_was_not_flushed(tmp_path, store):
    writer = imu_bag(tmp_path / "run", store, n=200, close=False)
    writer.flush()
    for k in range(200, 250):  # after the last flush: lost in the crash
        writer.write(0, 10_000 + k, bytes(store.serialize_cdr(imu_message(store, k * NS // 100, 1.0), IMU)))
    shutil.copytree(tmp_path / "run", tmp_path / "crashed")  # the files as a crash leaves them
    writer.close()
    with pytest.raises(BagError, match=r"no metadata.yaml .*--salvage"):
        open_bag(tmp_path / "crashed")
    with open_bag(tmp_path / "crashed", salvage=True) as reader:
        assert z_values(reader) == [float(k) for k in range(200)]
        assert reader.custom_data == {"note": "made by test_bag"}  # written at once, not at close


def test_queued_writer_keeps_every_message_of_every_thread(tmp_path, store):
    queued = QueuedBagWriter(BagWriter(tmp_path / "q"), flush_period_s=0.01)
    ids = [queued.add_topic(f"/t{i}", IMU, [Qos()]) for i in range(3)]
    data = bytes(store.serialize_cdr(imu_message(store, 0, 1.0), IMU))

    def produce(tid: int) -> None:
        for k in range(2000):
            queued.write(tid, tid * 10_000 + k, data)

    threads = [threading.Thread(target=produce, args=(tid,)) for tid in ids]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    queued.close()
    assert queued.error is None
    assert check_bag(tmp_path / "q") == {"/t0": 2000, "/t1": 2000, "/t2": 2000}


def test_sqlite3_and_ros1_bags_are_read(tmp_path, store):
    sqlite = tmp_path / "sqlite"
    with Writer2(sqlite, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conn = w.add_connection("/accel/front", IMU, typestore=store)
        for k in range(50):
            w.write(conn, k, bytes(store.serialize_cdr(imu_message(store, k * NS // 100, k / 2), IMU)))
    ros1 = get_typestore(Stores.ROS1_NOETIC)
    with Writer1(tmp_path / "run.bag") as w:
        conn = w.add_connection("/accel/front", IMU, typestore=ros1)
        for k in range(50):
            msg = imu_message(ros1, k * NS // 100, k / 2)
            w.write(conn, k + 1, bytes(ros1.serialize_ros1(msg, IMU)))
    for path, cdr in ((sqlite, True), (tmp_path / "run.bag", False)):
        with open_bag(path) as reader:
            assert reader.cdr is cdr
            assert z_values(reader) == [k / 2 for k in range(50)]


def test_the_indexed_fast_path_reads_what_anyreader_reads(tmp_path, store):
    """MCAP files are read through their message indexes; rosbags' AnyReader is the reference."""
    imu_bag(tmp_path / "run", store, n=900, chunk_size=20_000)
    names = ["/accel/rear", "/sim/ground_truth", "/accel/front"]
    with open_bag(tmp_path / "run") as reader:
        assert reader._indexed
        fast = list(reader.batches(names, size=500))
        reader._indexed = []
        slow = list(reader.batches(names, size=500))
    assert len(fast) > 2  # batches across chunks

    def flat(batches):
        return (
            np.concatenate([b.topic for b in batches]),
            np.concatenate([b.log_ns for b in batches]),
            [b.messages.message(i) for b in batches for i in range(len(b))],
        )

    (t1, l1, m1), (t2, l2, m2) = flat(fast), flat(slow)
    assert np.array_equal(t1, t2) and np.array_equal(l1, l2) and m1 == m2 and len(m1) == 1801


def test_a_queued_writer_left_open_closes_its_bag_when_the_program_ends(tmp_path):
    code = (
        "from rozyn_estimator.bag import BagWriter, QueuedBagWriter\n"
        f"q = QueuedBagWriter(BagWriter({str(tmp_path / 'left')!r}))\n"
        "t = q.add_topic('/x', 'std_msgs/msg/Float64')\n"
        "for k in range(100):\n"
        "    q.write(t, k, bytes([0, 1, 0, 0]) + bytes(8))\n"
        "raise SystemExit('an error on the way out: close() is never called')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    assert check_bag(tmp_path / "left") == {"/x": 100}
