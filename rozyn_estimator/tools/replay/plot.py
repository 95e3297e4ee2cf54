"""``estimates.png``: a run's estimates over time, from its ``updates.csv``.

``rozyn replay`` draws one per bag and ``rozyn demo`` one for its run. Five panels over
the message time: m, I_yy and l_f, each published estimate with its ±2σ band, the
ground truth (``/sim/ground_truth``) and the values the node published in the recording
(``/inertia``) when there are any; then the body modes' natural frequencies and damping
ratios. A full car's (its CSV has ``roll_inertia_kgm2``) has seven: m, I_xx, I_yy, l_f,
y_c and its three body modes. On every panel the updates that failed (no estimate:
identification failed, speed varied …) are red lines, those that published with a
warning orange ones, and the stretches where the window was still filling are shaded.

Columns are read by name (:data:`~rozyn_estimator.tools.replay.outputs.CSV_COLUMNS`), so
a CSV with more columns plots the same. Built on ``matplotlib.figure.Figure`` (no pyplot
state): safe in any thread or process.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes

PLOT_NAME = "estimates.png"
PARAMS = (
    ("mass_kg", "m", "kg"),
    ("pitch_inertia_kgm2", "I_yy", "kg m²"),
    ("cog_from_front_axle_m", "l_f", "m"),
)
FULL_PARAMS = (PARAMS[0], ("roll_inertia_kgm2", "I_xx", "kg m²"), *PARAMS[1:], ("cog_lateral_m", "y_c", "m"))
MODE_COLORS = (("tab:purple", "o"), ("tab:cyan", "s"), ("tab:olive", "^"))
WALL_CLOCK_S = 1e8  # stamps beyond this (1973) are wall-clock times: plotted from the first one
FAILED, WARNED, FILLING = "#d62728", "#ff7f0e", "0.85"


def matplotlib_available() -> bool:
    """Whether the plot can be drawn here (matplotlib is an optional dependency of replay)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class UpdateSeries:
    """The columns of ``updates.csv`` the plot uses, one entry per update.

    ``numbers`` maps a numeric column to its values (NaN where the cell is empty or the
    column is missing).
    """

    stamp_s: np.ndarray
    status: tuple[str, ...]
    published: np.ndarray
    numbers: dict[str, np.ndarray]
    params: tuple[tuple[str, str, str], ...] = PARAMS  # (column, symbol, unit), the layout's order
    modes: int = 2

    def column(self, name: str) -> np.ndarray:
        return self.numbers.get(name, np.full(self.stamp_s.size, np.nan))


def read_updates(path: Path) -> UpdateSeries:
    """The plot's columns of an ``updates.csv`` (by name).

    Args:
        path: the CSV.

    Returns:
        Its updates in file order.
    """
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
        columns = reader.fieldnames or []
    params = FULL_PARAMS if "roll_inertia_kgm2" in columns else PARAMS
    modes = 3 if "mode3_freq_hz" in columns else 2
    wanted = [f"{p}{s}" for p, _, _ in params for s in ("", "_std")]
    wanted += [f"mode{k}_{q}" for k in range(1, modes + 1) for q in ("freq_hz", "damping")]
    numbers = {
        name: np.array([_float(r.get(name, "")) for r in rows]) for name in wanted if rows and name in rows[0]
    }
    return UpdateSeries(
        stamp_s=np.array([_float(r["stamp_s"]) for r in rows]),
        status=tuple(r["status"] for r in rows),
        published=np.array([r["published"] == "1" for r in rows], dtype=bool),
        numbers=numbers,
        params=params,
        modes=modes,
    )


def _float(cell: str) -> float:
    try:
        return float(cell)
    except ValueError:
        return float("nan")


def plot_estimates(
    updates_csv: Path,
    png: Path,
    *,
    truth: Sequence[float] | Mapping[int, Sequence[float]] | None = None,
    recorded: Mapping[int, Sequence[float]] | None = None,
    title: str = "",
) -> Path:
    """Draw ``png`` from ``updates_csv``.

    Args:
        updates_csv: the run's ``updates.csv``.
        png: the figure to write.
        truth: the true (m, I_yy, l_f) (a full car's five), when known; or by stamp [ns] where
            it changed (a load change: drawn as steps).
        recorded: the node's published (m, I_yy, l_f) (the full car's five) by stamp [ns], when
            the bag holds them.
        title: the figure's title (e.g. the bag's name).

    Returns:
        ``png``.
    """
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    series = read_updates(updates_csv)
    t0 = _origin(series.stamp_s, recorded)
    t = series.stamp_s - t0
    panels = len(series.params) + 2
    fig = Figure(figsize=(10, 2.4 * panels), dpi=100, layout="constrained")
    axes = fig.subplots(panels, 1, sharex=True)
    for index, (ax, (name, symbol, unit)) in enumerate(zip(axes, series.params, strict=False)):
        _parameter_panel(ax, series, t, name, f"{symbol} [{unit}]", index, truth, recorded, t0)
    _modes_panels(axes[-2], axes[-1], series, t)
    for ax in axes:
        _mark_statuses(ax, series, t)
    handles: dict[str, Any] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(label, handle)
    fig.legend(handles.values(), handles.keys(), loc="outside lower center", ncol=5, fontsize=8)
    axes[-1].set_xlabel("message time [s]" if t0 == 0 else f"message time − {t0:.0f} s [s]")
    counts = _status_counts(series)
    fig.suptitle(f"{title}\n{counts}" if title else counts, fontsize=10)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png)
    return png


def _origin(stamp_s: np.ndarray, recorded: Mapping[int, Sequence[float]] | None) -> float:
    """0 for sim time; the first stamp (whole seconds) for wall-clock stamps."""
    first = [float(np.nanmin(stamp_s))] if stamp_s.size else []
    first += [min(recorded) / 1e9] if recorded else []
    start = min(first) if first else 0.0
    return float(np.floor(start)) if start > WALL_CLOCK_S else 0.0


def _parameter_panel(ax: Axes, series: UpdateSeries, t: np.ndarray, name: str, ylabel: str, index: int,
                     truth: Sequence[float] | Mapping[int, Sequence[float]] | None,
                     recorded: Mapping[int, Sequence[float]] | None, t0: float) -> None:
    value, std = series.column(name), series.column(f"{name}_std")
    ok = series.published & np.isfinite(value)
    if ok.any():
        lo, hi = value - 2 * std, value + 2 * std
        band = ok & np.isfinite(std)
        ax.fill_between(t[band], lo[band], hi[band], color="tab:blue", alpha=0.2, linewidth=0, label="±2σ")
        ax.plot(t[ok], value[ok], "o-", color="tab:blue", markersize=3, linewidth=1, label="estimate")
    if recorded:
        stamps = np.array(sorted(recorded), dtype=np.int64)
        values = np.array([recorded[s][index] for s in stamps])
        ax.plot(stamps / 1e9 - t0, values, "x", color="black", markersize=5, label="published by the node")
    if isinstance(truth, Mapping):  # steps at its changes, on to the last update
        changes = sorted(truth)
        xs = [c / 1e9 - t0 for c in changes] + [max(float(t.max(initial=0.0)), changes[-1] / 1e9 - t0)]
        ys = [truth[c][index] for c in changes]
        ax.step(xs, [*ys, ys[-1]], where="post", color="tab:green", linestyle="--", linewidth=1.2,
                label="truth")
    elif truth is not None:
        ax.axhline(truth[index], color="tab:green", linestyle="--", linewidth=1.2, label="truth")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def _modes_panels(freq_ax: Axes, damping_ax: Axes, series: UpdateSeries, t: np.ndarray) -> None:
    for k, (color, marker) in enumerate(MODE_COLORS[: series.modes], start=1):
        freq_ax.plot(t, series.column(f"mode{k}_freq_hz"), marker, color=color, markersize=3,
                     label=f"body mode {k}")
        damping_ax.plot(t, series.column(f"mode{k}_damping"), marker, color=color, markersize=3)
    freq_ax.set_ylabel("mode frequency [Hz]")
    damping_ax.set_ylabel("mode damping ratio")
    for ax in (freq_ax, damping_ax):
        ax.grid(alpha=0.3)


def _mark_statuses(ax: Axes, series: UpdateSeries, t: np.ndarray) -> None:
    """Failed updates red, warned ones orange, window filling shaded (labelled once per axes)."""
    failed = ~series.published & np.array([s != "OK" for s in series.status], dtype=bool)
    warned = series.published & np.array([s != "OK" for s in series.status], dtype=bool)
    filling = ~series.published & ~failed
    for mask, color, label in ((failed, FAILED, "failed"), (warned, WARNED, "warned")):
        for i, x in enumerate(t[mask]):
            ax.axvline(x, color=color, linewidth=1, alpha=0.6, label=label if i == 0 else None)
    previous = np.r_[t[:1], t[:-1]]
    first = True
    for start, end in _runs(filling):
        ax.axvspan(previous[start], t[end - 1], color=FILLING, alpha=0.5, linewidth=0,
                   label="window filling" if first else None)
        first = False


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) of each run of True."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _status_counts(series: UpdateSeries) -> str:
    statuses = np.array(series.status)
    published = int(series.published.sum())
    failed = int((~series.published & (statuses != "OK")).sum())
    warned = int((series.published & (statuses != "OK")).sum())
    return (f"{len(statuses)} updates: {published} published ({warned} with a warning), {failed} failed, "
            f"{len(statuses) - published - failed} while the window filled")
