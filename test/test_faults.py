"""Issue 14, "never crash, never mislead": each reported failure, reproduced as reported.

Each test failed before its fix (a traceback, a silently different number, a misleading
status or unbounded memory); now the outcome is a one-line error, a counted drop or a
status that says what happened.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import yaml
from bag_helpers import IMU, NS, flip_sign, imu_bag, imu_message, strip_crcs, z_values
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from rozyn_estimator import vehicle as vehicle_module
from rozyn_estimator.bag import SENSOR_QOS, BagWriter, FieldReader, open_bag
from rozyn_estimator.errors import BagError, ConfigError
from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.online import ERROR, OK, WARN, OnlineConfig, OnlineEstimator, pair_channels
from rozyn_estimator.online import estimator as estimator_module
from rozyn_estimator.tools import cli
from rozyn_estimator.vehicle import Vehicle, load_vehicle
from sim_node.simulation import SimConfig, Simulation

FAST = PipelineConfig(variance="none", refine="none")


@pytest.fixture(scope="module")
def store():
    return get_typestore(Stores.ROS2_JAZZY)


@pytest.fixture(scope="module")
def drive():
    """90 s of the Table 5-1 car at 100 Hz: stamps [ns] and (n, 2) accelerations."""
    block = Simulation(SimConfig(duration_s=90.0, seed=5)).run(90.0)
    return np.round(block.t_s * NS).astype(np.int64), block.accel_mps2


def _replay(capsys, *args: str) -> tuple[int, str, str]:
    code = cli.main(["replay", *args, "--no-bag", "--no-plot", "--method", "rozyn", "--window-s", "20",
                     "--update-period-s", "5"])
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(code: int, err: str) -> str:
    assert code == 1 and err.startswith("rozyn replay: error: ") and err.count("\n") == 1, err
    return err


# ---------------------------------------------------------------- item 3: damaged message data
def test_garbled_payloads_are_dropped_and_counted_also_with_salvage(tmp_path, store, drive, capsys):
    """Garbled CDR inside an intact chunk raised rosbags' SerdeError out of ``rozyn replay``."""
    stamps, accel = drive
    with BagWriter(tmp_path / "garbled") as writer:
        ids = [writer.add_topic(t, IMU, [SENSOR_QOS]) for t in ("/accel/front", "/accel/rear")]
        for k, t in enumerate(stamps.tolist()):
            for c in (0, 1):
                data = bytearray(store.serialize_cdr(imu_message(store, t, float(accel[k, c])), IMU))
                if (k, c) in ((100, 0), (2000, 1), (2001, 1)):
                    data[:4] = b"\x07\x07\x07\x07"  # Invalid or unsupported CDR encapsulation
                writer.write(ids[c], 10 + 2 * k + c, bytes(data))
    for salvage in ((), ("--salvage",)):
        out_dir = str(tmp_path / f"out{len(salvage)}")
        code, out, err = _replay(capsys, str(tmp_path / "garbled"), *salvage, "--out", out_dir)
        assert code == 0 and "Traceback" not in err, err
        assert "front: undecodable message: 1, rear: undecodable message: 2" in out
    with open_bag(tmp_path / "garbled") as reader:
        fields = FieldReader(reader.typestore, IMU, ["linear_acceleration.z"], reader.deserialize)
        batch = next(reader.batches(["/accel/front"], size=10_000))
        decoded = fields.decode(batch.messages)
        assert np.flatnonzero(~decoded.ok).tolist() == [100] and "cannot be decoded" in decoded.error
        assert np.isnan(fields.read(batch.messages)[1][100, 0])  # read: NaN, dropped as one
        assert np.array_equal(decoded.values[:100, 0], accel[:100, 0])


def test_a_zstd_chunk_with_flipped_bytes_is_an_error_naming_it_or_skipped_by_salvage(tmp_path, store):
    """Flipped bytes in a compressed chunk decompressed to garbage: SerdeError: Invalid string length."""
    imu_bag(tmp_path / "run", store, n=600, chunk_size=16_000)
    file = tmp_path / "run" / "run_0.mcap"
    good = file.read_bytes()
    with open_bag(tmp_path / "run") as reader:
        chunks = reader._indexed.summaries[0][1].chunk_indexes
        expected = z_values(reader)
    second = chunks[1]
    lo = second.chunk_start_offset + 100
    for at in range(lo, lo + second.compressed_size - 120, 97):
        data = bytearray(good)
        data[at] ^= 0xFF
        file.write_bytes(bytes(data))
        with open_bag(tmp_path / "run") as reader:
            try:
                assert z_values(reader) == expected  # a flip the data do not see
            except BagError as exc:
                assert f"chunk at byte {second.chunk_start_offset}" in str(exc) and "--salvage" in str(exc)
        with open_bag(tmp_path / "run", salvage=True) as reader:
            z = z_values(reader)
            assert z == expected or (reader.damage and set(z) < set(expected))


# ---------------------------------------------------------------- item 4: CRCs on the fast path
def test_a_flipped_sign_in_a_crc_protected_chunk_is_detected_by_default(tmp_path, store):
    """Before: the indexed fast path read the flipped sample; only --salvage checked the CRC."""
    imu_bag(tmp_path / "run", store, n=600, chunk_size=16_000, compression="none")
    file = tmp_path / "run" / "run_0.mcap"
    flip_sign(file, 321.0)  # front (or rear) sample 321
    with open_bag(tmp_path / "run") as reader, pytest.raises(BagError) as err:
        z_values(reader)
    assert "CRC does not match" in str(err.value) and "--salvage" in str(err.value)
    with open_bag(tmp_path / "run", salvage=True) as reader:
        z = z_values(reader)
        assert len(reader.damage) == 1 and "crc validation failed" in reader.damage[0]
        assert -321.0 not in z and 300 < len(z) < 600 and not reader.unverified


def test_a_message_index_pointing_at_another_channel_is_an_error(tmp_path, store):
    """The message indexes lie outside the CRC: an entry must match the record it points at."""
    imu_bag(tmp_path / "run", store, n=50)
    file = tmp_path / "run" / "run_0.mcap"
    with open_bag(tmp_path / "run") as reader:
        summary = reader._indexed.summaries[0][1]
    chunk = summary.chunk_indexes[0]
    front, rear = (cid for cid, ch in summary.channels.items() if ch.topic.startswith("/accel"))
    data = bytearray(file.read_bytes())
    at = [chunk.message_index_offsets[c] + 1 + 8 + 2 + 4 for c in (front, rear)]  # first entries
    data[at[0] + 8 : at[0] + 16] = data[at[1] + 8 : at[1] + 16]  # front's first offset: a rear record
    file.write_bytes(bytes(data))
    with open_bag(tmp_path / "run") as reader, pytest.raises(BagError, match="does not match its messages"):
        z_values(reader)


def test_a_bag_without_crcs_is_reported_unverified(tmp_path, store, capsys):
    imu_bag(tmp_path / "run", store, n=3000, chunk_size=100_000)
    with open_bag(tmp_path / "run") as reader:
        assert reader.unverified == []
        n = len(reader._indexed.summaries[0][1].chunk_indexes)
    strip_crcs(tmp_path / "run" / "run_0.mcap")
    note = f"run_0.mcap: {n} of {n} chunks carry no CRC: damage in them cannot be detected"
    for salvage in (False, True):
        with open_bag(tmp_path / "run", salvage=salvage) as reader:
            assert reader.unverified == [note]
            assert z_values(reader) == [float(k) for k in range(3000)]
    code, _, err = _replay(capsys, str(tmp_path / "run"), "--out", str(tmp_path / "out"))
    assert code == 0 and f"rozyn replay: warning: {note}" in err
    with Writer2(tmp_path / "sqlite", version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        conn = w.add_connection("/accel/front", IMU, typestore=store)
        w.write(conn, 1, bytes(store.serialize_cdr(imu_message(store, 0, 1.0), IMU)))
    with open_bag(tmp_path / "sqlite") as reader:
        assert [u.split(": ", 1)[1] for u in reader.unverified] == [
            "SQLite3 storage carries no checksums: damage cannot be detected"]


# ---------------------------------------------------------------- item 5: malformed files
@pytest.mark.parametrize(
    ("content", "words"),
    [
        (b"wheelbase_m: 2.8\n# caf\xe9\n", "not UTF-8 text (byte 0xe9 at position 22)"),
        (b"a: " + b"[" * 100_000 + b"]" * 100_000, "nested deeper than 32 levels"),
        (b"".join(b"  " * i + b"k%d:\n" % i for i in range(500)), "nested deeper than 32 levels"),
        (b"x: " + b"9" * 6000, "not valid YAML: Exceeds the limit"),
        (b"a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
         + b"".join(b"%c: &%c [%s]\n" % (98 + i, 98 + i, b", ".join([b"*%c" % (97 + i)] * 10))
                    for i in range(9))
         + b"wheelbase_m: *j\n", "more than 200000 values"),
        (b"wheelbase_m: [1, 2\n", "not valid YAML: while parsing a flow sequence"),
        (b"\x00\x01binary", "not valid YAML"),
    ],
    ids=["not-utf8", "deep-flow", "deep-block", "huge-int", "alias-bomb", "broken", "binary"],
)
def test_malformed_vehicle_files_are_one_line_errors(tmp_path, content, words):
    """Before: UnicodeDecodeError, RecursionError, minutes of parsing and printing."""
    path = tmp_path / "car.yaml"
    path.write_bytes(content)
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    text = str(err.value)
    assert text.startswith(f"{path}: ") and words in text and "\n" not in text and len(text) < 1000, text


def test_large_vehicle_files_are_refused_unread_and_unknown_keys_listed_briefly(tmp_path):
    """Before: 10 MB of unknown keys took 57 s and printed a 6.3 MB error."""
    path = tmp_path / "keys.yaml"
    line = "unknown_key_number_{}: 1\n"
    path.write_text("".join(line.format(i) for i in range(400_000)))  # 10 MB
    limit = vehicle_module.MAX_VEHICLE_FILE_BYTES
    too_large = rf"too large for a vehicle file \(more than {limit} bytes\)"
    with pytest.raises(ConfigError, match=too_large):
        load_vehicle(path)
    n = limit // len(line.format(99_999))
    path.write_text("".join(line.format(i) for i in range(n)))  # just under the limit
    with pytest.raises(ConfigError) as err:
        load_vehicle(path)
    assert f"and {n - 10} more; known: sprung_mass_kg" in str(err.value) and len(str(err.value)) < 2000


def test_malformed_metadata_yaml_and_missing_files_are_one_line_errors(tmp_path, store):
    """Before: a binary metadata.yaml raised UnicodeDecodeError; --salvage with a file missing
    FileNotFoundError."""
    imu_bag(tmp_path / "run", store, n=100)
    meta = tmp_path / "run" / "metadata.yaml"
    info = yaml.safe_load(meta.read_text())
    cases = {
        bytes(range(256)) * 4: "not UTF-8 text",
        b"a: " + b"[" * 10_000 + b"]" * 10_000: "nested deeper than 32 levels",
        b"rosbag2_bagfile_information: {relative_file_paths: 3}": "no list of file names",
        b"rosbag2_bagfile_information: {relative_file_paths: []}": "lists no storage files",
    }
    for content, words in cases.items():
        meta.write_bytes(content)
        for salvage in (False, True):
            with pytest.raises(BagError, match=words):
                open_bag(tmp_path / "run", salvage=salvage)
    info["rosbag2_bagfile_information"]["relative_file_paths"].append("run_1.mcap")
    meta.write_text(yaml.safe_dump(info))
    with pytest.raises(BagError, match=r"lists .*run_1.mcap, which is missing; --salvage reads the others"):
        open_bag(tmp_path / "run")
    with open_bag(tmp_path / "run", salvage=True) as reader:
        assert reader.damage == ["run_1.mcap: missing (listed in metadata.yaml)"]
        assert z_values(reader) == [float(k) for k in range(100)]
    (tmp_path / "run" / "run_0.mcap").unlink()
    with pytest.raises(BagError, match=r"which are missing$"):
        open_bag(tmp_path / "run", salvage=True)


# ---------------------------------------------------------------- item 6: one sensor silent
@pytest.mark.parametrize("rear", ["never heard", "dead after 10 s"])
def test_a_silent_sensor_does_not_grow_the_other_channel(rear):
    """Before: the front was trimmed only when an update fell due, i.e. never (221 MB an hour at 1 kHz)."""
    cfg = OnlineConfig(window_s=10.0, update_period_s=2.0)
    est = OnlineEstimator(Vehicle(), cfg, FAST)
    front = est._channels[0]
    held = []
    for second in range(300):  # 1 kHz, a second at a time
        t = (second * 1000 + np.arange(1000)) * 1_000_000
        est.add_batch(np.zeros(1000, int), t, np.sin(t / 1e8))
        if rear == "dead after 10 s" and second < 10:
            est.add_batch(np.ones(1000, int), t, np.cos(t / 1e8))
        held.append(front.stamps.size + len(front.new_stamps))
    bound = (3 * cfg.window_s + cfg.update_period_s) * 1000 + 1  # two windows, a period, a window of slack
    assert max(held) <= bound and held[-1] >= (2 * cfg.window_s + cfg.update_period_s) * 1000
    for second in range(300, 330):  # one by one, as the node feeds
        for k in range(0, 1000, 10):
            est.add(0, (second * 1000 + k) * 1_000_000, 1.0)
        assert front.stamps.size + len(front.new_stamps) <= bound
    assert est.health().level == WARN and "waiting for rear" in est.health().message


# ---------------------------------------------------------------- item 9: smaller ones
@pytest.mark.parametrize("rear_hz", [4.0, 2.0, 1.0])
def test_a_slow_second_sensor_with_a_short_window_is_a_status(rear_hz):
    """Before: ValueError (all the input array dimensions ...) in pairing at <= 4 Hz."""
    cfg = OnlineConfig(window_s=5.0, update_period_s=1.0, min_window_fill=0.05, max_gap_s=2.0)
    tf = np.arange(2000) * NS // 100
    tr = np.round(np.arange(int(20 * rear_hz)) * NS / rear_hz).astype(np.int64)
    vf, vr = np.sin(tf / 1e8), np.cos(tr / 1e8)
    grid, y, fs = pair_channels((tf[:500], vf[:500]), (tr[tr < 5 * NS], vr[tr < 5 * NS]), cfg)
    assert y.shape == (grid.size, 2) and np.all(np.isfinite(y)) and fs == pytest.approx(rear_hz)
    est = OnlineEstimator(Vehicle(), cfg, FAST)
    order = np.argsort(np.r_[tf, tr], kind="stable")
    jobs = est.add_batch(np.r_[np.zeros(tf.size, int), np.ones(tr.size, int)][order], np.r_[tf, tr][order],
                         np.r_[vf, vr][order])
    updates = [est.compute(job) for job, _ in jobs]
    assert updates and all(not u.published and "internal error" not in u.message for u in updates)


@pytest.mark.parametrize(
    ("option", "value", "words"),
    [("--window-s", "1e308", "window_s: must lie in [1, 3600] s, got 1e+308"),
     ("--speed-mps", "1e-308", "speed_mps: must be 0 (unknown) or at least 0.1 m/s, got 1e-308"),
     ("--speed-mps", "1e308", "speed_mps: must lie in [0, 150] m/s, got 1e+308")],
)
def test_overflowing_options_are_one_line_errors(tmp_path, store, capsys, option, value, words):
    """Before: OverflowError tracebacks (--speed-mps 1e-308: the wheelbase delay overflowed)."""
    imu_bag(tmp_path / "run", store, n=3000)  # 30 s: updates fall due
    code = cli.main(["replay", str(tmp_path / "run"), "--method", "rozyn", "--window-s", "20", option, value,
                     "--out", str(tmp_path / "out")])
    assert words in _one_line_error(code, capsys.readouterr().err)


def test_a_late_sample_is_counted_once(drive):
    """Before: a sample arriving 5 samples late was counted missing (its gap) and dropped."""
    stamps, accel = drive
    est = OnlineEstimator(Vehicle(), OnlineConfig(window_s=20.0, update_period_s=5.0), FAST)
    order = list(range(3000))
    order.insert(505, order.pop(500))  # the front's sample 500 arrives after its 505
    for j, k in enumerate(order):
        est.add(0, int(stamps[k]), float(accel[k, 0]))
        est.add(1, int(stamps[j]), float(accel[j, 1]))
    h = est.report()
    assert (h.values["missing_front"], h.values["dropped (front: out-of-order stamp)"]) == ("0", "1")
    assert h.message == "lost 1 samples since the last report (see dropped/missing)"


def test_an_all_nan_sensor_is_reported_as_invalid_not_silent(drive):
    """Before: "waiting for rear: no message yet" while every rear sample was NaN."""
    stamps, accel = drive
    est = OnlineEstimator(Vehicle(), OnlineConfig(window_s=20.0, update_period_s=5.0), FAST)
    for k in range(300):
        est.add(0, int(stamps[k]), float(accel[k, 0]))
        est.add(1, int(stamps[k]), float("nan"))
    assert est.health().message == "waiting for rear: all 300 samples invalid (non-finite value)"
    est.add(1, int(stamps[300]), 1.0)
    est.add(1, int(stamps[301]), float("inf"))
    assert est.health().message != "waiting for rear: no message yet"


def test_a_killed_recording_says_so_and_points_at_salvage(tmp_path, store, capsys):
    """A SIGKILLed recorder leaves no footer and no metadata.yaml: say so, point at --salvage."""
    writer = imu_bag(tmp_path / "run", store, n=2000, chunk_size=20_000, close=False)
    writer.flush()
    shutil.copytree(tmp_path / "run", tmp_path / "killed")  # the files as SIGKILL leaves them
    writer.close()
    err = _one_line_error(*_replay(capsys, str(tmp_path / "killed"), "--out", str(tmp_path / "o1"))[::2])
    assert "no metadata.yaml (the recording was not closed: killed or crashed?); --salvage" in err
    err = _one_line_error(*_replay(capsys, str(tmp_path / "killed" / "run_0.mcap"), "--out",
                                   str(tmp_path / "o2"))[::2])
    assert "ends before its MCAP footer, as a recording that was killed leaves it" in err
    assert "--salvage" in err
    code, out, _ = _replay(capsys, str(tmp_path / "killed"), "--salvage", "--out", str(tmp_path / "o3"))
    assert code == 0 and "without its summary (the recording was not closed)" in out


# ---------------------------------------------------------------- diagnostics never lie
def test_an_update_that_raises_is_an_error_until_a_good_one_follows(drive, monkeypatch):
    """Before: the exception escaped compute(); the node logged it and /diagnostics kept saying OK."""
    stamps, accel = drive
    est = OnlineEstimator(Vehicle(), OnlineConfig(window_s=30.0, update_period_s=5.0), FAST)
    real = estimator_module.compute_update
    calls = []

    def flaky(*args, **kwargs):
        calls.append(1)
        if len(calls) in (8, 9):
            raise ValueError("all the input array dimensions must match exactly")
        return real(*args, **kwargs)

    monkeypatch.setattr(estimator_module, "compute_update", flaky)
    levels = []
    for k in range(len(stamps)):
        t, (a, b) = int(stamps[k]), accel[k].tolist()
        for job in (*est.add(0, t, a), *est.add(1, t, b)):
            update = est.compute(job)
            h = est.report()
            levels.append((update.level, h.level, h.message))
            if len(calls) in (8, 9):
                assert update.level == ERROR and not update.published and est.last_update is update
                assert est.health() == h and h.level == ERROR
                assert h.message == ("update failed (internal error, please report): ValueError: all the "
                                     "input array dimensions must match exactly")
                assert est.report().level == ERROR  # said until a good update follows
    assert levels[6] == levels[9] == (OK, OK, "estimate published")  # before, and the next good one


def test_a_failed_estimate_is_reported_until_a_good_one_follows(drive):
    stamps, accel = drive
    est = OnlineEstimator(Vehicle(), OnlineConfig(window_s=20.0, update_period_s=5.0), FAST)
    flat = np.full_like(accel, 9.81)  # a constant window: identification fails
    reports = []
    for k in range(len(stamps)):
        a = flat[k] if k < 2000 else accel[k]
        for job in (*est.add(0, int(stamps[k]), float(a[0])), *est.add(1, int(stamps[k]), float(a[1]))):
            update = est.compute(job)
            reports.append((update.level, [est.report(), est.report()]))
    failed = [r for u, r in reports if u == WARN]
    assert failed
    assert all(h.level == WARN and h.message.startswith("identification failed") for r in failed for h in r)
    good = [r for u, r in reports if u == OK and r[0].message == "estimate published"]
    assert good and all(h.level == OK for r in good for h in r)


def test_a_non_finite_estimate_is_never_published(drive, monkeypatch):
    """The pipeline's contract is finite, positive numbers; if it ever broke it, the update says so."""
    from rozyn_estimator.method import Estimate
    from rozyn_estimator.online import update as update_module

    stamps, accel = drive
    est = OnlineEstimator(Vehicle(), OnlineConfig(window_s=10.0, update_period_s=5.0), FAST)
    bad = Estimate("ok", params=np.array([1000.0, np.inf, 1.2]), covariance=np.eye(3))
    monkeypatch.setattr(update_module, "estimate", lambda *a, **k: bad)
    jobs = est.add_batch(np.repeat([0, 1], 2000), np.r_[stamps[:2000], stamps[:2000]],
                         np.r_[accel[:2000, 0], accel[:2000, 1]])
    updates = [est.compute(job) for job, _ in jobs if job.due_ns >= 10 * NS]
    assert updates
    assert all(u.level == ERROR and not u.published and "non-finite" in u.message for u in updates)


def test_dropping_undecodable_messages_counts_them_per_channel():
    est = OnlineEstimator(Vehicle(), OnlineConfig(), FAST)
    est.drop(1, "undecodable message", 3)
    assert est.dropped == {"rear: undecodable message": 3}
    assert est.health().message == \
        "waiting for rear: all 3 samples invalid (undecodable message); front: no message yet"

