"""Launch-free ROS test helpers: a private context, an EventsExecutor and a probe node.

Importing this module sets localhost-only discovery; each test module passes its own
ROS domain so parallel runs do not cross-talk.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

import pytest
import rclpy
from rclpy.context import Context
from rclpy.experimental import EventsExecutor

# Each test process takes a block of twelve ROS domains (10-213: away from the default 0 and
# from the node benchmark's, 222-231), chosen by its pid; each module has fixed
# offsets in it, so the modules of one run never share a domain.
_BLOCK = 12
_DOMAIN_BASE = 10 + (os.getpid() % 17) * _BLOCK
OFFSETS = {"nodes": 0, "recorder": 4, "demo": 6, "docs": 7, "shutdown": 8, "fullcar": 10}


def domain(module: str, extra: int = 0) -> int:
    """This process' ROS domain for a test module (``extra``: a further private one)."""
    offset = OFFSETS[module] + extra
    assert extra >= 0 and offset < _BLOCK, (module, extra)
    return _DOMAIN_BASE + offset


class Ros:
    """Nodes on one executor in a private context; ``add`` them, ``spin_until`` a condition."""

    def __init__(self, domain: int) -> None:
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.executor = EventsExecutor(context=self.context)
        self._nodes: list[Any] = []
        self.probe = self.add(rclpy.create_node("probe", context=self.context))

    def add(self, node: Any) -> Any:
        self._nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin_until(self, condition: Callable[[], Any], timeout_s: float) -> Any:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not condition():
            self.executor.spin_once(timeout_sec=0.02)
        return condition()

    def close(self) -> None:
        for node in self._nodes:
            node.destroy_node()
        self.executor.shutdown()
        rclpy.shutdown(context=self.context)


@contextmanager
def ros_session(domain: int) -> Iterator[Ros]:
    ros = Ros(domain)
    try:
        yield ros
    finally:
        ros.close()


def ros_fixture(domain_id: int) -> Any:
    """A ``ros`` fixture for a test module: a private context on ``domain_id``, an
    EventsExecutor and a probe node; torn down after each test."""

    @pytest.fixture
    def ros() -> Iterator[Ros]:
        with ros_session(domain_id) as session:
            yield session

    return ros
