"""What ``rozyn demo`` shows and writes: a line per estimate against the truth, the summary,
``updates.csv`` (as ``rozyn replay`` writes it) and ``estimates.png``.

The half car's line has m, I_yy and l_f; the full car's m, I_xx, I_yy, l_f and the lateral
CoG y_c (which is often 0: its error is in m, not in %). Everything is read from the
messages a probe node received (``sim/ground_truth``, ``inertia``, ``inertia/covariance``),
as any subscriber would read them.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rozyn_estimator.online import Layout
from rozyn_estimator.tools.options import drive_label
from rozyn_estimator.tools.replay.outputs import inertia_values

NS = 1_000_000_000
HALF_ROWS = (("m", 1, " kg"), ("Iyy", 1, " kg m²"), ("lf", 4, " m"))  # (symbol, digits, unit)
FULL_ROWS = (("m", 1, " kg"), ("Ixx", 1, " kg m²"), ("Iyy", 1, " kg m²"), ("lf", 4, " m"), ("yc", 4, " m"))


@dataclass
class Seen:
    """What the demo's probe received, and the lines printed so far."""

    layout: Layout
    truth: Any = None
    truth_steps: dict[int, tuple[float, ...]] = field(default_factory=dict)  # stamp [ns] -> the truth since
    inertia: dict[int, Any] = field(default_factory=dict)
    covariance: dict[int, Any] = field(default_factory=dict)
    printed: set[int] = field(default_factory=set)
    lines: list[str] = field(default_factory=list)
    last_status: str = ""

    @property
    def rows(self) -> tuple[tuple[str, int, str], ...]:
        return FULL_ROWS if self.layout.full else HALF_ROWS

    def take_truth(self, msg: Any) -> None:
        """A ``sim/ground_truth`` message: the truth from its stamp on."""
        self.truth = msg
        self.truth_steps[msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec] = self.values(msg)

    def values(self, msg: Any) -> tuple[float, ...]:
        """An InertiaStamped's parameters in the layout's order (the front axle at x = 0)."""
        return inertia_values(msg.inertia, 0.0, self.layout.full)


def row(label: str, value: float, std: float, truth: float, digits: int, unit: str = "",
        absolute: bool = False) -> str:
    """``m = 1000.3 ± 0.3 (+0.03 %) kg``; ``absolute``: the error in the value's unit."""
    err = f"{value - truth:+.{digits}f}" if absolute else f"{(value / truth - 1.0) * 100.0:+.2f} %"
    return f"{label} = {value:.{digits}f} ± {std:.{digits}f} ({err}){unit}"


def print_new(seen: Seen) -> None:
    """Print a line for each estimate whose inertia and covariance have both arrived."""
    if seen.truth is None:
        return
    truth = seen.values(seen.truth)
    k = len(truth)
    for stamp in sorted(set(seen.inertia) & set(seen.covariance) - seen.printed):
        values, cov = seen.values(seen.inertia[stamp]), seen.covariance[stamp]
        std = [max(cov.data[i * (k + 1)], 0.0) ** 0.5 for i in range(k)]
        cells = [row(label, values[i], std[i], truth[i], digits, unit, absolute=label == "yc")
                 for i, (label, digits, unit) in enumerate(seen.rows)]
        line = "  ".join([f"t = {stamp / NS:6.1f} s", *cells])
        seen.printed.add(stamp)
        seen.lines.append(line)
        print(line, flush=True)


def summary(seen: Seen, args: argparse.Namespace, wall_s: float, held_s: float, max_pending: int) -> int:
    """The closing lines; the exit status (1 when no estimate was published)."""
    print()
    if seen.truth is not None:
        truth = seen.values(seen.truth)
        print("truth: " + ", ".join(f"{label} = {value:g}{unit}"
                                    for (label, _, unit), value in zip(seen.rows, truth, strict=True)))
    print(f"the simulator waited {held_s:.1f} s for the estimator and the recorder "
          f"(at most {max_pending} updates waiting)")
    if not seen.printed:
        print(f"no estimate was published ({seen.last_status or 'no diagnostics'})")
        return 1
    print(f"{len(seen.printed)} estimates in {wall_s:.1f} s wall time "
          f"({args.duration_s / wall_s:.1f}x real time); last: {seen.lines[-1]}")
    return 0


def write_outputs(out_dir: Path, updates: Sequence[Any], seen: Seen, args: argparse.Namespace) -> None:
    """``updates.csv`` as ``rozyn replay`` writes it, and ``estimates.png``; prints their paths."""
    import csv

    from rozyn_estimator.tools.replay.outputs import ReplayedUpdate, csv_columns, csv_row
    from rozyn_estimator.tools.replay.plot import PLOT_NAME, matplotlib_available, plot_estimates

    out_dir.mkdir(parents=True, exist_ok=True)
    with (out_dir / "updates.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(csv_columns(seen.layout))
        for update in sorted(updates, key=lambda u: u.stamp_ns):
            writer.writerow(csv_row(ReplayedUpdate(update, update.stamp_ns), seen.layout))
    print(f"\nwrote {out_dir / 'updates.csv'}")
    if args.plot is False or not updates or (args.plot is None and not matplotlib_available()):
        return
    car = "full car, " if seen.layout.full else ""
    png = plot_estimates(
        out_dir / "updates.csv", out_dir / PLOT_NAME,
        truth=seen.truth_steps if len(seen.truth_steps) > 1 else None if seen.truth is None else
        seen.values(seen.truth),
        title=f"rozyn demo: {car}{args.road} road ({args.amplitudes}), {drive_label(args)}",
    )
    print(f"plot: {png}")
