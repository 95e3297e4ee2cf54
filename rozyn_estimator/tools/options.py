"""Command-line options shared by the tools that simulate runs (``rozyn trial``, ``rozyn compare``).

Only argparse here: the commands that use these options import the simulator themselves.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence


def add_run_options(p: argparse.ArgumentParser, roads: Sequence[str], amplitudes: str) -> None:
    """Road, speed, duration and rate of simulated runs (``trial`` and ``compare``)."""
    p.add_argument("--road", choices=roads, default="iso", help="road model (default: iso)")
    p.add_argument("--road-class", default="A", metavar="A..H", help="ISO 8608 class (default: A)")
    p.add_argument("--amplitudes", choices=("fixed", "gaussian"), default=amplitudes,
                   help="fixed: the thesis' generator; gaussian: a true Gaussian road "
                        f"(default: {amplitudes})")
    p.add_argument("--laplace-nu", type=float, default=1.0, metavar="NU",
                   help="Laplace road: variance of the section gamma variable (default: 1.0)")
    p.add_argument("--waviness", type=float, default=2.0, metavar="W", help="ISO waviness w (default: 2)")
    p.add_argument("--speed-kmh", type=float, default=100.0, help="vehicle speed (default: 100)")
    p.add_argument("--duration-s", type=float, default=100.0, help="measurement time (default: 100)")
    p.add_argument("--rate-hz", type=float, default=100.0, help="accelerometer rate (default: 100)")


def add_vehicle_option(p: argparse.ArgumentParser) -> None:
    """``--vehicle FILE.yaml``: the vehicle's parameters (default: the thesis' Table 5-1)."""
    p.add_argument("--vehicle", metavar="FILE.yaml", help="vehicle parameters (default: thesis Table 5-1)")
