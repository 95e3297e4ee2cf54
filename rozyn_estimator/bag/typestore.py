"""Message definitions for bags: rosbags' Jazzy typestore, custom types, topic names.

ROS-free. The writer takes each topic's schema (full ``ros2msg`` text) and RIHS01 type
hash from here; the readers deserialise with :func:`default_typestore` plus what a bag
defines itself.
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path
from typing import Any


@cache
def default_typestore() -> Any:
    """The ROS 2 Jazzy message definitions shipped with rosbags.

    Returns:
        rosbags' ``Typestore`` for ``Stores.ROS2_JAZZY`` (one shared instance; custom
        types found by :func:`message_definition` are registered into it).
    """
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def absolute_topic(name: str) -> str:
    """``accel/front`` -> ``/accel/front`` (names relative to the root namespace).

    Args:
        name: a topic name, relative or absolute.

    Returns:
        The absolute name.
    """
    return name if name.startswith("/") else f"/{name}"


def message_definition(msgtype: str) -> tuple[str, str]:
    """(full ``ros2msg`` text, RIHS01 hash) of a message type, or ``("", "")`` if unknown.

    Looks in rosbags' Jazzy store first, then for ``share/<pkg>/msg/<Type>.msg`` files
    under ``AMENT_PREFIX_PATH`` (custom messages of a sourced workspace).

    Args:
        msgtype: e.g. ``sensor_msgs/msg/Imu``.

    Returns:
        The schema text and type hash MCAP and ``metadata.yaml`` carry.
    """
    store = default_typestore()
    if msgtype not in store.fielddefs and not _register_from_ament(store, msgtype):
        return "", ""
    text, _ = store.generate_msgdef(msgtype, ros_version=2)
    return text, store.hash_rihs01(msgtype)


def _register_from_ament(store: Any, msgtype: str) -> bool:
    """Register ``msgtype`` (and the types it uses) from ``.msg`` files; False if not found."""
    from rosbags.typesys import get_types_from_msg

    pending, found = [msgtype], {}
    while pending:
        name = pending.pop()
        if name in store.fielddefs or name in found:
            continue
        pkg, _, short = name.partition("/msg/")
        text = next(
            (
                path.read_text()
                for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
                if prefix and (path := Path(prefix, "share", pkg, "msg", f"{short}.msg")).is_file()
            ),
            None,
        )
        if text is None:
            return False
        types = get_types_from_msg(text, name)
        found.update(types)
        for _, fields in types.values():
            for _, (_kind, detail) in fields:
                pending += [t for t in _type_names(detail) if "/msg/" in t]
    store.register(found)
    return True


def _type_names(detail: Any) -> list[str]:
    """Message type names referenced by a rosbags field definition."""
    if isinstance(detail, str):
        return [detail]
    if isinstance(detail, tuple):
        return [name for part in detail for name in _type_names(part)]
    return []
