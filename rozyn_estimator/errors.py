"""Exception types of rozyn_estimator.

Each carries a message a user can act on; the edges (CLI, nodes) turn them into one
clear line and an exit code or a diagnostic.
"""

from __future__ import annotations


class RozynError(Exception):
    """Base class of every error this package raises on purpose."""


class ConfigError(RozynError, ValueError):
    """A parameter or configuration file is invalid; the message names the field."""


class BagError(RozynError):
    """A bag cannot be read or written; the message names the file and the reason."""
