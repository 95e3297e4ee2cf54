"""The vectorised CDR field reader against rosbags' deserialiser (no DDS)."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from rozyn_estimator.bag import FieldReader
from rozyn_estimator.errors import ConfigError

NS = 1_000_000_000
MIXED = """
std_msgs/Header header
string label
uint8 flag
float64[] samples
int16[3] triple
geometry_msgs/Vector3 v
string[] names
float32 after_names
"""


def _never(raw, msgtype):
    raise AssertionError("the slow path was used")


@pytest.fixture(scope="module")
def store():
    ts = get_typestore(Stores.ROS2_JAZZY)
    ts.register(get_types_from_msg(MIXED, "test_msgs/msg/Mixed"))
    return ts


def _imu(store, k: int, frame: str):
    t = store.types
    header = t["std_msgs/msg/Header"](
        stamp=t["builtin_interfaces/msg/Time"](sec=k, nanosec=7 * k), frame_id=frame
    )
    vec = t["geometry_msgs/msg/Vector3"]
    cov = np.arange(9, dtype=float)
    return t["sensor_msgs/msg/Imu"](
        header=header,
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=cov,
        angular_velocity=vec(x=1.0, y=2.0, z=3.0),
        angular_velocity_covariance=cov,
        linear_acceleration=vec(x=0.5 * k, y=-k, z=9.81 + k / 1000),
        linear_acceleration_covariance=cov,
    )


def _mixed(store, k: int):
    t = store.types
    header = t["std_msgs/msg/Header"](
        stamp=t["builtin_interfaces/msg/Time"](sec=k, nanosec=k), frame_id="f" * (k % 5)
    )
    return t["test_msgs/msg/Mixed"](
        header=header,
        label="x" * (k % 7),
        flag=k % 256,
        samples=np.arange(k % 4, dtype=float),
        triple=np.array([k, -k, 3], dtype=np.int16),
        v=t["geometry_msgs/msg/Vector3"](x=k, y=2.0 * k, z=-1.5 * k),
        names=["a" * (k % 3)] * (k % 2),
        after_names=float(k) / 4,
    )


def test_imu_fields_with_any_frame_id_length(store):
    """Every frame_id length 0..20 (every alignment of the doubles), in one batch."""
    msgs = [_imu(store, k, "l" * (k % 21)) for k in range(200)]
    data = [bytes(store.serialize_cdr(m, "sensor_msgs/msg/Imu")) for m in msgs]
    fields = ["linear_acceleration.z", "linear_acceleration.x", "angular_velocity.y"]
    reader = FieldReader(store, "sensor_msgs/msg/Imu", fields, _never)
    assert reader.vectorised and reader.has_header
    stamps, values = reader.read(data)
    assert stamps.tolist() == [k * NS + 7 * k for k in range(200)]
    expected = [[m.linear_acceleration.z, m.linear_acceleration.x, m.angular_velocity.y] for m in msgs]
    assert np.array_equal(values, np.array(expected))


def test_strings_sequences_and_arrays_before_the_field(store):
    msgs = [_mixed(store, k) for k in range(60)]
    data = [bytes(store.serialize_cdr(m, "test_msgs/msg/Mixed")) for m in msgs]
    fast = FieldReader(store, "test_msgs/msg/Mixed", ["flag", "v.z", "v.x"], _never)
    assert fast.vectorised
    stamps, values = fast.read(data)
    assert np.array_equal(values, [[m.flag, m.v.z, m.v.x] for m in msgs])
    assert stamps.tolist() == [k * NS + k for k in range(60)]
    # behind a sequence of strings the walk stops: the slow path reads it, same numbers
    slow = FieldReader(store, "test_msgs/msg/Mixed", ["after_names", "v.y"], store.deserialize_cdr)
    assert not slow.vectorised
    assert np.array_equal(slow.read(data)[1], [[m.after_names, m.v.y] for m in msgs])


def test_damaged_or_big_endian_messages_fall_back_to_the_slow_path(store):
    data = [bytes(store.serialize_cdr(_imu(store, k, "imu"), "sensor_msgs/msg/Imu")) for k in range(3)]
    reader = FieldReader(store, "sensor_msgs/msg/Imu", ["linear_acceleration.z"], store.deserialize_cdr)
    big = [b"\x00\x00" + d[2:] for d in data]  # a big-endian header: the vectorised walk must not read it
    calls = []

    def deserialize(raw, msgtype):
        calls.append(raw)
        return store.deserialize_cdr(data[len(calls) - 1], msgtype)

    reader._deserialize = deserialize
    _, values = reader.read(big)
    assert len(calls) == 3 and values[:, 0].tolist() == [9.81 + k / 1000 for k in range(3)]


def test_messages_without_header_have_no_stamp(store):
    data = [
        bytes(store.serialize_cdr(store.types["std_msgs/msg/Float64"](data=x), "std_msgs/msg/Float64"))
        for x in (1.5, -2.0)
    ]
    reader = FieldReader(store, "std_msgs/msg/Float64", ["data"], _never)
    stamps, values = reader.read(data)
    assert stamps is None and values[:, 0].tolist() == [1.5, -2.0]


@pytest.mark.parametrize(
    ("field", "words"),
    [
        ("linear_acceleration.w", ["no field 'w'", "linear_acceleration.z", "angular_velocity.x"]),
        ("header.frame_id", ["is a string, not a number"]),
        ("linear_acceleration", ["is a message (geometry_msgs/msg/Vector3), not a number"]),
        ("orientation_covariance", ["is an array, not a number"]),
        ("header.frame_id.x", ["is a string, not a message"]),
    ],
)
def test_fields_that_are_not_numbers_are_refused_clearly(store, field, words):
    with pytest.raises(ConfigError) as err:
        FieldReader(store, "sensor_msgs/msg/Imu", [field], store.deserialize_cdr)
    for word in words:
        assert word in str(err.value)
