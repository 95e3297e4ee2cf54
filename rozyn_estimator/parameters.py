"""Parameters described once: description, unit, range and read-only flag next to the field.

A configuration dataclass declares each of its fields with :func:`param` and calls
:func:`check` in ``__post_init__``. Everything that shows or takes the value uses that
one description: the ROS nodes declare their parameters from it
(:mod:`rozyn_estimator.ros.glue`), replay, demo and a bag's stored configuration build
the same dataclasses (so the same rules apply), and the parameter reference's tables
(docs/parameters.md) are generated from it (``rozyn_estimator.tools.param_tables``).

:func:`check` first checks each field against its description (type, finite, range,
choices, length), then the class' cross-field rules, each a predicate evaluated lazily
and in order: a rule that raises counts as failed. Every failure, however malformed the
value, is a :class:`~rozyn_estimator.errors.ConfigError` naming the parameter by its
ROS name (``pipeline.freq_band_hz: needs 0 < min < max, got (1.0,)``).

ROS-free (the simulator imports it too).

Example:
    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class Window:
    ...     PARAM_PREFIX = "demo."
    ...     length_s: float = param(10.0, "window length", unit="s", low=0.0, open_low=True)
    ...     def __post_init__(self) -> None:
    ...         check(self)
    >>> Window(5).length_s
    5.0
    >>> Window(-1.0)
    Traceback (most recent call last):
    ...
    rozyn_estimator.errors.ConfigError: demo.length_s: must be > 0 s, got -1.0
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from rozyn_estimator.errors import ConfigError

KEY = "rozyn_estimator.param"
Rule = tuple[str, Callable[[Any], bool], str]  # (field, predicate on the config, what it needs)
_MAX_SHOWN = 200  # characters of a refused value shown in a message


@dataclass(frozen=True)
class Param:
    """How a field is described and checked.

    ``low``/``high`` bound numbers (and each item of a tuple), inclusive unless
    ``open_low``; ``ros_name`` is the last part of the ROS parameter name (default: the
    field's name; ``""``: not a ROS parameter).
    """

    description: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    choices: tuple[str, ...] = ()
    read_only: bool = False
    ros_name: str | None = None
    length: int | None = None

    def range_text(self) -> str:
        """The range as a table cell: ``[0.1, 3600]``, ``> 0``, ``a | b``."""
        if self.choices:
            return " \\| ".join(self.choices)
        if self.low is not None and self.high is not None:
            return f"{'(' if self.open_low else '['}{_g(self.low)}, {_g(self.high)}]"
        if self.low is not None:
            return f"{'>' if self.open_low else '≥'} {_g(self.low)}"
        if self.high is not None:
            return f"≤ {_g(self.high)}"
        return ""


def param(default: Any = dataclasses.MISSING, description: str = "", *,
          default_factory: Any = dataclasses.MISSING, **spec: Any) -> Any:
    """A dataclass field with its :class:`Param` description (keywords as Param's)."""
    meta = {KEY: Param(description, **spec)}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def spec_of(f: dataclasses.Field[Any]) -> Param | None:
    return f.metadata.get(KEY)


def prefix_of(config: Any) -> str:
    """The dotted prefix of a config class' parameter names (``pipeline.`` …)."""
    return str(getattr(config, "PARAM_PREFIX", ""))


def name_of(config: Any, f: dataclasses.Field[Any]) -> str:
    spec = spec_of(f)
    return prefix_of(config) + (spec.ros_name if spec is not None and spec.ros_name else f.name)


def check(config: Any, rules: Sequence[Rule] = ()) -> None:
    """Validate (and coerce: ints to floats, lists to tuples) a config dataclass in place.

    Raises:
        ConfigError: naming the first invalid parameter and its rule.
    """
    for f in dataclasses.fields(config):
        spec = spec_of(f)
        if spec is None:
            continue
        value = getattr(config, f.name)
        fixed = coerce(name_of(config, f), spec, _default(f), value)
        if fixed is not value:
            object.__setattr__(config, f.name, fixed)
    for name, predicate, need in rules:
        try:
            ok = bool(predicate(config))
        except Exception:  # a malformed value: the rule fails, it does not crash
            ok = False
        if not ok:
            f = next(x for x in dataclasses.fields(config) if x.name == name)
            raise ConfigError(f"{name_of(config, f)}: {need}, got {shown(getattr(config, name))}")


def coerce(name: str, spec: Param, default: Any, value: Any) -> Any:
    """``value`` as the type of ``default``, checked against ``spec``; ConfigError otherwise."""
    if dataclasses.is_dataclass(default):
        if not isinstance(value, type(default)):
            raise ConfigError(f"{name}: expected {type(default).__name__} settings, got {shown(value)}")
        return value
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{name}: expected true or false, got {shown(value)}")
        return value
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"{name}: expected a string, got {shown(value)}")
        if spec.choices and value not in spec.choices:
            raise ConfigError(f"{name}: must be one of {', '.join(spec.choices)}, got {shown(value)}")
        return value
    if isinstance(default, tuple):
        if isinstance(value, str | bytes | Mapping) or not hasattr(value, "__iter__"):
            raise ConfigError(f"{name}: expected a list of numbers, got {shown(value)}")
        items = tuple(value)
        if spec.length is not None and len(items) != spec.length:
            raise ConfigError(f"{name}: expected {spec.length} numbers, got {shown(value)}")
        if default and isinstance(default[0], str):
            if not all(isinstance(x, str) for x in items):
                raise ConfigError(f"{name}: expected a list of strings, got {shown(value)}")
            return items
        return tuple(_number(name, spec, x, integer=False) for x in items)
    return _number(name, spec, value, integer=isinstance(default, int))


def _number(name: str, spec: Param, value: Any, integer: bool) -> Any:
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, int | float):
        unit = f" in {spec.unit}" if spec.unit else ""
        raise ConfigError(f"{name}: expected {kind}{unit}, got {shown(value)}")
    if integer and not isinstance(value, int):
        raise ConfigError(f"{name}: expected {kind}, got {shown(value)}")
    given = value
    if not integer:
        try:
            value = float(value)
        except OverflowError:
            raise ConfigError(f"{name}: too large, got {shown(value)}") from None
        if not math.isfinite(value):
            raise ConfigError(f"{name}: must be finite, got {shown(value)}")
    low, high = spec.low, spec.high
    outside = (low is not None and (value <= low if spec.open_low else value < low)) or \
        (high is not None and value > high)
    if outside:
        raise ConfigError(f"{name}: {range_rule(spec)}, got {shown(given)}")
    return value


def range_rule(spec: Param) -> str:
    """The range as a rule: ``must lie in [1, 3600] s``, ``must be > 0``."""
    u = _unit(spec)
    if spec.low is not None and spec.high is not None:
        return f"must lie in {'(' if spec.open_low else '['}{_g(spec.low)}, {_g(spec.high)}]{u}"
    if spec.low is not None:
        return f"must be {'>' if spec.open_low else '>='} {_g(spec.low)}{u}"
    return f"must be <= {_g(spec.high)}{u}"


def _unit(spec: Param) -> str:
    return f" {spec.unit}" if spec.unit else ""


def _g(x: float | None) -> str:
    """A bound as written: integers in full (2147483647, not 2.14748e+09), others short."""
    if x is None:
        return ""
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


def shown(value: Any) -> str:
    """A refused value as a message shows it (bounded: a huge value prints a short text)."""
    text = repr(value)
    return text if len(text) <= _MAX_SHOWN else text[: _MAX_SHOWN - 3] + "..."


def _default(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    raise TypeError(f"parameter field {f.name} has no default")


# ------------------------------------------------------------------ flat (ROS) names
@dataclass(frozen=True)
class Flat:
    """One parameter of a config tree under its flat ROS name."""

    name: str
    value: Any  # the current value, tuples as lists (as ROS holds them)
    spec: Param


def flatten(config: Any) -> list[Flat]:
    """Every described field of a (nested) config dataclass, by flat ROS name, in order.

    Fields with ``ros_name=""`` are left out; nested configs contribute their own fields
    under their own prefix.
    """
    out: list[Flat] = []
    for f in dataclasses.fields(config):
        spec = spec_of(f)
        if spec is None or spec.ros_name == "":
            continue
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            out += flatten(value)
        else:
            out.append(Flat(name_of(config, f), list(value) if isinstance(value, tuple) else value, spec))
    return out


def build(default: Any, values: Mapping[str, Any]) -> Any:
    """A config like ``default`` with the flat ROS ``values`` that name its fields, checked.

    Values not given keep the default's; nested configs are built from the same values.

    Raises:
        ConfigError: naming the first invalid parameter.
    """
    changes = {}
    for f in dataclasses.fields(default):
        spec = spec_of(f)
        if spec is None or spec.ros_name == "":
            continue
        current = getattr(default, f.name)
        if dataclasses.is_dataclass(current):
            changes[f.name] = build(current, values)
        elif (name := name_of(default, f)) in values:
            changes[f.name] = values[name]
    return dataclasses.replace(default, **changes)  # checked by the class' __post_init__
