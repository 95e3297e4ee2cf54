"""Helpers of the bag tests: what every bag we write must satisfy (rosbag2 metadata fit for
``ros2 bag play``, read back by rosbags' AnyReader and by the ``mcap`` reader with the ROS 2
decoder), and messages like the sim's."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from rozyn_estimator.bag import LATCHED_QOS, SENSOR_QOS, BagWriter, FieldReader, default_typestore

NS = 1_000_000_000
IMU = "sensor_msgs/msg/Imu"

QOS_KEYS = {
    "history",
    "depth",
    "reliability",
    "durability",
    "deadline",
    "lifespan",
    "liveliness",
    "liveliness_lease_duration",
    "avoid_ros_namespace_conventions",
}
TOP_KEYS = {
    "version",
    "storage_identifier",
    "duration",
    "starting_time",
    "message_count",
    "topics_with_message_count",
    "compression_format",
    "compression_mode",
    "relative_file_paths",
    "files",
    "custom_data",
    "ros_distro",
}


def check_bag(path: Path) -> dict[str, int]:
    """Assert the bag at ``path`` is complete and interoperable; its per-topic counts."""
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert set(info) >= TOP_KEYS, TOP_KEYS - set(info)
    assert info["version"] == 9 and info["storage_identifier"] == "mcap" and info["ros_distro"] == "jazzy"
    assert info["compression_mode"] == "" and info["compression_format"] == ""  # chunk compression only
    counts = {}
    for entry in info["topics_with_message_count"]:
        meta = entry["topic_metadata"]
        assert meta["name"].startswith("/") and meta["serialization_format"] == "cdr"
        assert isinstance(meta["offered_qos_profiles"], list)  # v9: a list of maps
        for qos in meta["offered_qos_profiles"]:
            assert set(qos) == QOS_KEYS and set(qos["deadline"]) == {"sec", "nsec"}
        if meta["type"] in default_typestore().fielddefs:
            assert meta["type_description_hash"] == default_typestore().hash_rihs01(meta["type"])
        counts[meta["name"]] = entry["message_count"]
    assert sum(counts.values()) == info["message_count"]
    files = [path / name for name in info["relative_file_paths"]]
    assert [f.name for f in files] == [f["path"] for f in info["files"]] == [f"{path.name}_0.mcap"]
    assert all(f.is_file() for f in files)

    with AnyReader([path], default_typestore=default_typestore()) as reader:
        seen, times = Counter(), []
        for conn, t, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            seen[conn.topic] += 1
            times.append(t)
    assert dict(seen) == {k: v for k, v in counts.items() if v}
    if times:
        assert info["starting_time"]["nanoseconds_since_epoch"] == min(times)
        assert info["duration"]["nanoseconds"] == max(times) - min(times)

    with files[0].open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert reader.get_header().profile == "ros2"
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr"
            assert {"offered_qos_profiles", "topic_type_hash"} <= set(channel.metadata)
            assert summary.schemas[channel.schema_id].encoding == "ros2msg"
        assert {c.compression for c in summary.chunk_indexes} <= {"zstd"}
        decoded = Counter(ch.topic for _, ch, _, msg in reader.iter_decoded_messages() if msg is not None)
    assert dict(decoded) == dict(seen)
    return counts


def imu_message(store, stamp_ns: int, z: float, frame_id: str = "accel_front_link",
                rates: tuple[float, float] | None = None):
    """A sensor_msgs/Imu as the sim publishes it (rosbags message object); with ``rates`` its
    gyros' ``angular_velocity.x`` and ``.y``."""
    t = store.types
    stamp = t["builtin_interfaces/msg/Time"](sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    vec = t["geometry_msgs/msg/Vector3"]
    cov = np.zeros(9)
    unknown = np.array([-1.0, *[0.0] * 8])
    ros1 = {"seq": 0} if "seq" in dict(store.fielddefs["std_msgs/msg/Header"][1]) else {}
    return t["sensor_msgs/msg/Imu"](
        header=t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id, **ros1),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=unknown,
        angular_velocity=vec(x=0.0, y=0.0, z=0.0) if rates is None else vec(x=rates[0], y=rates[1], z=0.0),
        angular_velocity_covariance=unknown if rates is None else cov,
        linear_acceleration=vec(x=0.0, y=0.0, z=z),
        linear_acceleration_covariance=cov,
    )


def twist_message(store, stamp_ns: int, vx: float):
    t = store.types
    stamp = t["builtin_interfaces/msg/Time"](sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    vec = t["geometry_msgs/msg/Vector3"]
    return t["geometry_msgs/msg/TwistStamped"](
        header=t["std_msgs/msg/Header"](stamp=stamp, frame_id="base_link"),
        twist=t["geometry_msgs/msg/Twist"](linear=vec(x=vx, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)),
    )


def inertia_message(store, stamp_ns: int, m: float, iyy: float, com_x: float):
    """A geometry_msgs/InertiaStamped (the sim's ground truth, the node's estimate)."""
    t = store.types
    stamp = t["builtin_interfaces/msg/Time"](sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    nan = float("nan")
    return t["geometry_msgs/msg/InertiaStamped"](
        header=t["std_msgs/msg/Header"](stamp=stamp, frame_id="base_link"),
        inertia=t["geometry_msgs/msg/Inertia"](
            m=m,
            com=t["geometry_msgs/msg/Vector3"](x=com_x, y=0.0, z=nan),
            ixx=nan,
            ixy=0.0,
            ixz=nan,
            iyy=iyy,
            iyz=0.0,
            izz=nan,
        ),
    )


def strip_crcs(file: Path) -> None:
    """Zero the CRC of every chunk and of the data section, as a writer without CRCs leaves them."""
    import struct

    with file.open("rb") as f:
        summary = make_reader(f).get_summary()
    data = bytearray(file.read_bytes())
    for chunk in summary.chunk_indexes:
        crc_at = chunk.chunk_start_offset + 1 + 8 + 8 + 8 + 8  # opcode, length, start, end, size
        data[crc_at : crc_at + 4] = bytes(4)
    footer = len(data) - 8 - (1 + 8 + 8 + 8 + 4)  # magic, then the footer record
    summary_start = struct.unpack_from("<Q", data, footer + 9)[0]
    data_end = summary_start - (1 + 8 + 4)  # the DataEnd record: opcode, length, crc
    assert data[data_end] == 0x0F
    data[data_end + 9 : data_end + 13] = bytes(4)
    file.write_bytes(bytes(data))


def flip_sign(file: Path, value: float) -> int:
    """Flip the sign of the first float64 ``value`` in the file (an uncompressed chunk); its offset."""
    import struct

    data = bytearray(file.read_bytes())
    at = data.find(struct.pack("<d", value))
    assert at > 0, value
    data[at + 7] ^= 0x80
    file.write_bytes(bytes(data))
    return at


def imu_bag(path: Path, store, n: int = 300, chunk_size: int = 1 << 20, close: bool = True,
            compression: str = "zstd") -> BagWriter:
    """Front/rear Imu at 100 Hz (z = k), a latched truth, custom data."""
    writer = BagWriter(path, chunk_size=chunk_size, compression=compression)
    ids = [writer.add_topic(t, IMU, [SENSOR_QOS]) for t in ("/accel/front", "/accel/rear")]
    truth = writer.add_topic("/sim/ground_truth", "geometry_msgs/msg/InertiaStamped", [LATCHED_QOS])
    writer.set_custom_data("note", "made by test_bag")
    inertia = inertia_message(store, 0, 1000.0, 2000.0, -1.2)
    writer.write(truth, 1, bytes(store.serialize_cdr(inertia, "geometry_msgs/msg/InertiaStamped")))
    for k in range(n):
        for c, tid in enumerate(ids):
            msg = imu_message(store, k * NS // 100, float(k), f"accel_{c}")
            writer.write(tid, 10 + 2 * k + c, bytes(store.serialize_cdr(msg, IMU)))
    if close:
        writer.close()
    return writer


def z_values(reader, topic="/accel/front") -> list[float]:
    """``linear_acceleration.z`` of every message of ``topic`` (NaN: could not be decoded)."""
    info = reader.topic(topic)
    fr = FieldReader(
        reader.typestore, info.msgtype, ["linear_acceleration.z"], reader.deserialize, cdr=reader.cdr
    )
    out = []
    for batch in reader.batches([topic], size=100):
        out += fr.read(batch.messages)[1][:, 0].tolist()
    return out


def write_imu_bag(path: Path, accel_z: np.ndarray, gyro_x: np.ndarray, gyro_y: np.ndarray) -> None:
    """A rosbag2 MCAP of one ``/imu/data`` topic at 100 Hz from 1 s on (:func:`imu_message`s)."""
    store = default_typestore()
    with BagWriter(path) as writer:
        topic = writer.add_topic("/imu/data", IMU, [SENSOR_QOS])
        samples = zip(accel_z.tolist(), gyro_x.tolist(), gyro_y.tolist(), strict=True)
        for k, (az, gx, gy) in enumerate(samples):
            ns = NS + k * NS // 100
            msg = imu_message(store, ns, az, "imu_link", (gx, gy))
            writer.write(topic, ns, bytes(store.serialize_cdr(msg, IMU)))
