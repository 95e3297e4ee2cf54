"""Parameter values -> typed configs: the checks both nodes, the recorder and replay share.

ROS-free (plain values in, dataclasses out), so the simulator node and the offline
tools may import it. Every error is a ConfigError naming the parameter.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from typing import Any

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.vehicle import Vehicle, load_vehicle, vehicle_from_mapping


def number(name: str, value: Any) -> float:
    """A numeric parameter value as float (integers are fine)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{name}: expected a number, got {value!r}")
    return float(value)


def check_choice(name: str, value: Any, options: Iterable[str]) -> str:
    options = tuple(options)
    if value not in options:
        raise ConfigError(f"{name}: must be one of {', '.join(options)}, got {value!r}")
    return value


def flat_fields(prefix: str, config: Any) -> list[tuple[str, Any]]:
    """(dotted name, ROS parameter value) of every field of a (nested) config dataclass."""
    out = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        name = f"{prefix}.{f.name}"
        if dataclasses.is_dataclass(value):
            out += flat_fields(name, value)
        else:
            out.append((name, list(value) if isinstance(value, tuple) else value))
    return out


def build_config(prefix: str, default: Any, values: Mapping[str, Any]) -> Any:
    """A config dataclass like ``default`` from dotted parameter values, checked."""
    fields = {}
    for f in dataclasses.fields(default):
        name, current = f"{prefix}.{f.name}", getattr(default, f.name)
        value = values.get(name, current)
        if dataclasses.is_dataclass(current):
            value = build_config(name, current, values)
        elif isinstance(current, float):
            value = number(name, value)
        elif isinstance(current, tuple):
            items = value if isinstance(value, list | tuple) else [value]
            floats = bool(current) and isinstance(current[0], float)
            value = tuple(number(name, x) if floats else x for x in items)
        fields[f.name] = value
    try:
        return type(default)(**fields)
    except (TypeError, ValueError) as exc:
        text = str(exc)
        raise ConfigError(text if text.startswith(f"{prefix}.") else f"{prefix}: {text}") from None


def vehicle_from_parameters(values: Mapping[str, Any]) -> Vehicle:
    """The vehicle from ``vehicle_file`` (when set) or the ``vehicle.<field>`` values."""
    if values.get("vehicle_file"):
        return load_vehicle(values["vehicle_file"])
    return vehicle_from_mapping(
        {k.removeprefix("vehicle."): v for k, v in values.items() if k.startswith("vehicle.")},
        source="parameters",
    )
