"""The parameter reference's tables (``docs/parameters.md``), generated from the parameters'
descriptions.

Each node's parameters are described once, next to their fields (``param(...)`` in the
config dataclasses); this renders them as Markdown tables between markers in the page:

    .venv/bin/python -m rozyn_estimator.tools.param_tables          # check the page is current
    .venv/bin/python -m rozyn_estimator.tools.param_tables --write  # rewrite its tables

A test keeps the page in sync with the descriptions (and the descriptions with what the
nodes declare).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rozyn_estimator.parameters import Flat, Param, flatten

PAGE = Path(__file__).resolve().parents[2] / "docs" / "parameters.md"
VEHICLE_FILE = Flat("vehicle_file", "", Param(
    "vehicle YAML (flat or ROS params); when set it overrides the vehicle.* parameters", read_only=True))


def node_parameters() -> dict[str, list[Flat]]:
    """Table name -> the parameters it lists (the nodes' own, then their shared vehicle: the
    half car's, or with ``vehicle.model`` full the full car's)."""
    from rozyn_estimator.online import EstimatorConfig
    from rozyn_estimator.ros.estimator_node import NodeOptions
    from rozyn_estimator.ros.recorder_node import RecorderOptions
    from rozyn_estimator.sensors import SENSORS_PARAMETER_HELP
    from rozyn_estimator.vehicle import Vehicle
    from rozyn_estimator.vehicle_full import MODEL_PARAM, FullVehicle
    from sim_node.node import NODE_DEFAULTS, SimNodeOptions

    model = Flat("vehicle.model", "half", MODEL_PARAM)

    def without_vehicle(config: Any) -> list[Flat]:
        return [f for f in flatten(config) if not f.name.startswith("vehicle.")]

    return {
        "estimator_node": [*flatten(NodeOptions()), *without_vehicle(EstimatorConfig()), VEHICLE_FILE],
        "sim_node": [*flatten(SimNodeOptions()), *without_vehicle(NODE_DEFAULTS), VEHICLE_FILE],
        "bag_recorder": flatten(RecorderOptions()),
        "vehicle": [model, *flatten(Vehicle()),
                    Flat("vehicle.sensors.names", [], Param(SENSORS_PARAMETER_HELP, read_only=True))],
        "vehicle_full": [model, *flatten(FullVehicle())],
    }


def _default(value: Any) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_default(v) for v in value) + "]"
    if value == "":
        return '""'
    return str(value)


def table(params: Sequence[Flat]) -> str:
    """One Markdown table, rows sorted by name."""
    lines = ["| parameter | default | unit | range | description |", "|---|---|---|---|---|"]
    for p in sorted(params, key=lambda f: f.name):
        spec = p.spec
        text = spec.description + (" (read-only)" if spec.read_only else "")
        lines.append(f"| `{p.name}` | {_default(p.value)} | {spec.unit} | {spec.range_text()} | {text} |")
    return "\n".join(lines)


def _marked(name: str) -> re.Pattern[str]:
    return re.compile(rf"(<!-- parameters:{name} -->\n)(.*?)(<!-- /parameters:{name} -->)", re.S)


def render(page: str) -> str:
    """``page`` with every marked table regenerated."""
    for name, params in node_parameters().items():
        found = _marked(name).search(page)
        if found is None:
            raise ValueError(f"{PAGE.name} lacks its <!-- parameters:{name} --> block")
        page = page[: found.start(2)] + table(params) + "\n" + page[found.end(2):]
    return page


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"rewrite {PAGE.name}'s tables")
    args = parser.parse_args(argv)
    text = PAGE.read_text()
    new = render(text)
    if args.write:
        PAGE.write_text(new)
        print(f"wrote {PAGE}")
        return 0
    if new != text:
        print(f"{PAGE}'s parameter tables are out of date: run with --write", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
