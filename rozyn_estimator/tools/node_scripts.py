"""The nodes' console scripts: ``estimator_node``, ``sim_node`` and ``bag_recorder``.

Each first catches SIGINT and SIGTERM (:class:`~rozyn_estimator.ros.stop.StopRequest`,
standard library only), then imports its node, which takes seconds (rclpy, numpy,
scipy), and spins it (:func:`rozyn_estimator.ros.glue.spin_node`). So Ctrl-C or SIGTERM
at any moment once this module runs, start-up included, ends the node in order with exit
status 0. (Before it runs, in the interpreter's own start-up and the ROS wheels' re-exec,
a signal has its default effect.) The handlers stay installed until the process exits.

SIGUSR1 prints every thread's Python stack to stderr and the node runs on (``kill -USR1
<pid>``): what a node that does not stop is doing, without stopping it.
"""

from __future__ import annotations

import faulthandler
import importlib
import signal

from rozyn_estimator.ros.stop import StopRequest

# executable -> "module:node class"
NODES = {
    "estimator_node": "rozyn_estimator.ros.estimator_node:EstimatorNode",
    "sim_node": "sim_node.node:SimNode",
    "bag_recorder": "rozyn_estimator.ros.recorder_node:BagRecorder",
}


def run(executable: str) -> int:
    """Catch the stop signals, import the node of ``executable``, spin it; the exit status."""
    stop = StopRequest().install()
    if hasattr(signal, "SIGUSR1"):
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    module, _, cls = NODES[executable].partition(":")
    from rozyn_estimator.ros.glue import spin_node

    return spin_node(getattr(importlib.import_module(module), cls), stop=stop)


def estimator_node() -> int:
    """The ``estimator_node`` executable."""
    return run("estimator_node")


def sim_node() -> int:
    """The ``sim_node`` executable."""
    return run("sim_node")


def bag_recorder() -> int:
    """The ``bag_recorder`` executable."""
    return run("bag_recorder")
