"""YAML files read safely (bounded in size, nesting and nodes; UTF-8 checked), and messages
kept to one bounded line: a vehicle file, a ROS 2 parameter file or a bag's metadata can hold
anything."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml

from rozyn_estimator.errors import ConfigError, RozynError


def one_line(text: str, limit: int = 2000) -> str:
    """A message as one bounded line: what the user cannot see (newlines, control characters)
    escaped, the end cut after ``limit`` characters (text from a file can be anything)."""
    text = text[: 4 * limit]
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


MAX_YAML_DEPTH = 32  # nesting of mappings and sequences (a vehicle in a ROS 2 parameter file: 4)
MAX_YAML_NODES = 200_000  # scalars, mappings and sequences, aliases counted as what they repeat
_LOADER: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's: 50x faster


def load_yaml_file(path: Path, *, max_bytes: int, what: str, error: type[RozynError] = ConfigError) -> Any:
    """A YAML file read safely: bounded in size, nesting and nodes, UTF-8 checked.

    Malformed files (binary, not UTF-8, nested too deep to parse, a YAML bomb of
    aliases, too large) are refused before they can take long or print much.

    Args:
        path: the file.
        max_bytes: the largest file accepted.
        what: what the file is, for messages (``vehicle file``).
        error: the error type raised (:class:`ConfigError`, or the caller's).

    Returns:
        The document (None for an empty one).

    Raises:
        RozynError: ``error`` with one line naming the file and the problem.
    """
    name = one_line(str(path))
    try:
        with path.open("rb") as f:
            raw = f.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"{name}: cannot read {what}: {exc.strerror or exc}") from None
    if len(raw) > max_bytes:
        raise error(f"{name}: too large for a {what} (more than {max_bytes} bytes)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{name}: not a {what}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at position "
                    f"{exc.start})") from None
    try:
        problem = _yaml_shape_problem(text)
        data = None if problem else yaml.load(text, Loader=_LOADER)  # a safe loader
    except (yaml.YAMLError, ValueError) as exc:  # ValueError: e.g. an integer of 5000 digits
        raise error(f"{name}: not valid YAML: {_yaml_error(exc)}") from None
    if problem:
        raise error(f"{name}: refused as a {what}: {problem}")
    return data


def _yaml_error(exc: Exception) -> str:
    """A YAML error on one line: what, and where (PyYAML's own text spans several lines)."""
    if isinstance(exc, yaml.MarkedYAMLError):
        mark = exc.problem_mark or exc.context_mark
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        text = ": ".join(str(part) for part in (exc.context, exc.problem) if part) + where
    else:
        text = " ".join(str(exc).split())
    return one_line(text, 300)


def _yaml_shape_problem(text: str) -> str | None:
    """Why the document is refused unread: nested deeper than MAX_YAML_DEPTH, or more
    than MAX_YAML_NODES nodes, aliases counted as the nodes they repeat (libyaml's parser
    is iterative: the check cannot itself recurse). None when it may be read."""
    depth: list[tuple[str | None, int]] = []  # the open collections: (anchor, nodes before)
    sizes: dict[str, int] = {}  # anchor -> nodes under it
    nodes = 0
    for event in _events(text):
        if event is None:
            return f"nested deeper than {MAX_YAML_DEPTH} levels"
        if isinstance(event, yaml.CollectionStartEvent):
            depth.append((event.anchor, nodes))
            nodes += 1
            if len(depth) > MAX_YAML_DEPTH:
                return f"nested deeper than {MAX_YAML_DEPTH} levels"
        elif isinstance(event, yaml.CollectionEndEvent):
            anchor, before = depth.pop()
            if anchor is not None:
                sizes[anchor] = nodes - before
        elif isinstance(event, yaml.ScalarEvent):
            nodes += 1
            if event.anchor is not None:
                sizes[event.anchor] = 1
        elif isinstance(event, yaml.AliasEvent):
            nodes += sizes.get(event.anchor or "", 1)
        if nodes > MAX_YAML_NODES:
            return f"more than {MAX_YAML_NODES} values (aliases counted as what they repeat)"
    return None


def _events(text: str) -> Iterator[yaml.Event | None]:
    """``yaml.parse``'s events, then None where PyYAML (>= 6.0.4) refuses a nesting deeper
    than its own limit: its scanner looks ahead of the events, so that limit can strike
    before :func:`_yaml_shape_problem` has counted MAX_YAML_DEPTH levels."""
    try:
        yield from yaml.parse(text, Loader=_LOADER)
    except yaml.MarkedYAMLError as exc:
        if "nesting depth" not in str(exc.problem or ""):
            raise
        yield None
