"""Property-based test of the bag reader on mutated bags (hypothesis; see ``test_fuzz.py``).

Small bags (zstd and uncompressed chunks) have bytes flipped, zeroed, cut, inserted or
truncated, their ``metadata.yaml`` deleted, garbled or made to list a missing file, and
are read in normal or salvage mode as ``rozyn replay`` reads them: only ``BagError`` and
``ConfigError`` may escape, each one bounded line, and a bag read without an error (and
not reported unverified) holds only the recorded messages, none altered.
"""

from __future__ import annotations

import shutil
from collections import Counter
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from bag_helpers import IMU, NS, imu_message, twist_message
from fuzz_helpers import budgets, one_line, run
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore

from rozyn_estimator.bag import LATCHED_QOS, SENSOR_QOS, BagWriter, FieldReader, open_bag
from rozyn_estimator.errors import BagError, ConfigError

TOPICS = ["/accel/front", "/accel/rear", "/sim/speed", "/sim/ground_truth"]


@cache
def bags(root: Path) -> dict[str, tuple[Path, list[tuple[str, int, bytes]]]]:
    """Small bags (zstd and uncompressed chunks) and the messages each holds."""
    store = get_typestore(Stores.ROS2_JAZZY)
    out = {}
    for compression in ("zstd", "none"):
        path = root / f"bag-{compression}"
        messages = []
        with BagWriter(path, compression=compression, chunk_size=6000) as writer:
            ids = {t: writer.add_topic(t, IMU, [SENSOR_QOS]) for t in TOPICS[:2]}
            ids[TOPICS[2]] = writer.add_topic(TOPICS[2], "geometry_msgs/msg/TwistStamped")
            ids[TOPICS[3]] = writer.add_topic(TOPICS[3], "geometry_msgs/msg/InertiaStamped", [LATCHED_QOS])
            writer.set_custom_data("note", "fuzz")
            for k in range(150):
                for topic in TOPICS[:3] if k % 10 == 0 else TOPICS[:2]:
                    msg = twist_message(store, k * NS // 100, 27.0) if topic == TOPICS[2] else \
                        imu_message(store, k * NS // 100, 9.81 + k / 64, f"f{k % 5}")
                    data = bytes(store.serialize_cdr(msg, "geometry_msgs/msg/TwistStamped"
                                                     if topic == TOPICS[2] else IMU))
                    messages.append((topic, 1000 + 10 * len(messages), data))
                    writer.write(ids[topic], messages[-1][1], data)
        out[compression] = (path, messages)
    return out


@st.composite
def mutations(draw: st.DrawFn) -> dict[str, Any]:
    """Which bag, what is done to its MCAP file and its metadata.yaml, and which mode reads it."""
    edits = draw(st.lists(st.tuples(
        st.sampled_from(["flip", "flip", "zero", "cut", "insert", "delete", "truncate"]),
        st.floats(0.0, 1.0), st.integers(1, 64), st.binary(min_size=1, max_size=16)), max_size=4))
    meta = draw(st.sampled_from(["keep", "keep", "keep", "delete", "garble", "binary", "rewrite"]))
    return {"bag": draw(st.sampled_from(["zstd", "none"])), "edits": edits, "meta": meta,
            "meta_edit": (draw(st.floats(0.0, 1.0)), draw(st.binary(max_size=8))),
            "salvage": draw(st.booleans())}


def _mutated(m: dict[str, Any], root: Path) -> Path:
    source, _ = bags(root)[m["bag"]]
    target = root / "mutated"
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(source, target)
    file = target / f"{source.name}_0.mcap"
    data = bytearray(file.read_bytes())
    for kind, where, size, payload in m["edits"]:
        if not data:
            break
        at = min(int(where * len(data)), len(data) - 1)
        if kind == "flip":
            data[at] ^= payload[0] or 0xFF
        elif kind == "zero":
            data[at:at + size] = bytes(len(data[at:at + size]))
        elif kind == "cut":
            data[at:at + size] = b""
        elif kind == "insert":
            data[at:at] = payload
        elif kind == "delete":
            del data[at:at + 1]
        else:
            del data[at:]
    file.write_bytes(bytes(data))
    meta = target / "metadata.yaml"
    where, payload = m["meta_edit"]
    if m["meta"] == "delete":
        meta.unlink()
    elif m["meta"] == "garble":
        text = bytearray(meta.read_bytes())
        at = int(where * len(text))
        text[at:at + len(payload)] = payload
        meta.write_bytes(bytes(text))
    elif m["meta"] == "binary":
        meta.write_bytes(payload * 50)
    elif m["meta"] == "rewrite":
        info = yaml.safe_load(meta.read_text())
        info["rosbag2_bagfile_information"]["relative_file_paths"] = [payload.hex() or "x.mcap", file.name]
        meta.write_text(yaml.safe_dump(info))
    return target


def read_everything(path: Path, salvage: bool) -> tuple[list[tuple[str, int, bytes]], list[str]]:
    """Every message of the bag as (topic, receive time, bytes), decoded as replay decodes them;
    the bag's notes of what is unverified. Only BagError and ConfigError may escape."""
    with open_bag(path, salvage=salvage) as reader:
        for note in [*reader.damage, *reader.unverified]:
            one_line(note)
        names = [n for n in reader.topics if n in TOPICS]
        out: list[tuple[str, int, bytes]] = []
        for batch in reader.batches(names, size=97):
            for i in range(len(batch)):
                out.append((names[batch.topic[i]], int(batch.log_ns[i]), batch.messages.message(i)))
            for k, name in enumerate(names):
                info = reader.topics[name]
                sel = np.flatnonzero(batch.topic == k)
                if info.msgtype == IMU:
                    fields = FieldReader(reader.typestore, IMU, ["linear_acceleration.z"], reader.deserialize,
                                         cdr=reader.cdr)
                    decoded = fields.decode(batch.messages.take(sel))
                    assert decoded.values.shape == (sel.size, 1)
                else:
                    for i in sel.tolist():
                        try:
                            reader.deserialize(batch.messages.message(i), info.msgtype)
                        except BagError as exc:
                            one_line(str(exc))
        return out, reader.unverified


@pytest.mark.parametrize("examples", budgets(40))
def test_bag_reader_on_mutated_bags(examples, tmp_path):
    def check(m: dict[str, Any]) -> None:
        path = _mutated(m, tmp_path)
        try:
            got, unverified = read_everything(path, m["salvage"])
        except (BagError, ConfigError) as exc:
            one_line(str(exc))
            return
        original = Counter(bags(tmp_path)[m["bag"]][1])
        if not unverified:  # read without an error: recorded messages only, none made up
            assert not Counter(got) - original, "a damaged message was read as if it were intact"

    run(examples, mutations(), check, "bag reader")
