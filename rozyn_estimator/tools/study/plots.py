"""Figures of ``rozyn study`` (matplotlib, Agg backend, PNG).

The thesis' chapter 5 figures, from a study's summaries and trials:

- ``std_<road>.png``: std of each estimate over speed x measurement time (Figs 5-11 to
  5-13, 5-20 to 5-22, as heatmaps rather than surfaces: every number is readable);
- ``std_lines_<road>.png``: the same std against time (one line per speed) and against
  speed (one line per time): velocity (in)dependence and the growth at short times;
- ``bias_<road>.png``: bias of the mean estimate vs truth [%];
- ``precision_<road>.png``: the std as a share of the truth against time (a line per
  speed; the shortest drive for 1 % marked) and, when the method publishes a std, its
  95 % coverage, published and statistical;
- ``std_ratio_laplace_iso.png``: std on the Laplace road over std on the ISO road;
- ``hist_<cell>.png``, ``box_<cell>.png``: estimates and errors of one cell
  (Figs 5-7 to 5-10, 5-16 to 5-19);
- ``acf_<cell>.png``: the cell's normalised autocorrelations (Figs 5-3, 5-4, 5-14, 5-15);
- ``failures.png``: failed trials per cell, only when there are any.

A panel per parameter of the study's model (the half car's three, the full car's five);
the autocorrelations per accelerometer (front and rear, or the four corners).

Figures are built on ``matplotlib.figure.Figure`` directly (no pyplot state), so this
module is safe to use from any thread or process.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib import colors, ticker
from matplotlib.figure import Figure

from rozyn_estimator.tools.study.correlations import CellCorrelations
from rozyn_estimator.tools.study.precision import TARGET_PCT, TARGET_SIGMAS, shortest_drives
from rozyn_estimator.tools.study.results import TrialRow
from rozyn_estimator.tools.study.settings import Cell, StudySettings
from rozyn_estimator.tools.study.summary import CellSummary

matplotlib.use("Agg")

DPI = 100


def road_label(settings: StudySettings, road: str) -> str:
    """E.g. 'ISO 8608 class A, fixed amplitudes' or 'Laplace ν = 1 (class A), gaussian amplitudes'."""
    if road == "laplace":
        return (f"Laplace ν = {settings.laplace_nu:g} (class {settings.road_class}), "
                f"{settings.amplitudes} amplitudes")
    return f"ISO 8608 class {settings.road_class}, {settings.amplitudes} amplitudes"


def cell_slug(cell: Cell | tuple[float, float]) -> str:
    speed, duration = (cell.speed_kmh, cell.duration_s) if isinstance(cell, Cell) else cell
    return f"{speed:g}kmh_{duration:g}s"


def plot_study(
    fig_dir: Path, settings: StudySettings, summaries: Sequence[CellSummary], rows: Sequence[TrialRow],
    correlations: Sequence[CellCorrelations], pmap: Callable[..., Iterable[Any]] = map,
) -> list[Path]:
    """Write every figure of a study into ``fig_dir``; returns their paths.

    ``pmap`` renders the figures (e.g. a process pool's ``map``: they are independent).
    """
    fig_dir.mkdir(parents=True, exist_ok=True)
    tasks: list[tuple[str, Callable[..., Figure], tuple[Any, ...]]] = []
    for road in settings.roads:
        tasks += [(f"std_{road}", std_heatmaps, (settings, summaries, road)),
                  (f"std_lines_{road}", std_lines, (settings, summaries, road)),
                  (f"bias_{road}", bias_heatmaps, (settings, summaries, road)),
                  (f"precision_{road}", precision_lines, (settings, summaries, road))]
    if {"iso", "laplace"} <= set(settings.roads):
        tasks.append(("std_ratio_laplace_iso", std_ratio_heatmaps, (settings, summaries)))
    if correlations:
        slug = cell_slug(correlations[0].cell)
        cells = [c.cell for c in correlations]
        cell_rows = [r for r in rows if r.cell in cells]
        tasks += [(f"hist_{slug}", histograms, (settings, cell_rows, cells)),
                  (f"box_{slug}", error_boxplot, (settings, cell_rows, cells)),
                  (f"acf_{slug}", correlation_overlay, (settings, correlations))]
    if any(s.failures for s in summaries):
        tasks.append(("failures", failure_heatmaps, (settings, summaries)))
    return list(pmap(_render, [(fig_dir / f"{name}.png", fn, args) for name, fn, args in tasks]))


def _render(task: tuple[Path, Callable[..., Figure], tuple[Any, ...]]) -> Path:
    path, fn, args = task
    fn(*args).savefig(path, dpi=DPI)
    return path


def grid_values(
    settings: StudySettings, summaries: Sequence[CellSummary], road: str, stat: str
) -> np.ndarray:
    """(n_speeds, n_durations, ...) array of a summary statistic; NaN where a cell has no results."""
    shape = np.shape(getattr(summaries[0], stat)) if summaries else ()
    out = np.full((len(settings.speeds_kmh), len(settings.durations_s), *shape), np.nan)
    speed_index = {v: i for i, v in enumerate(settings.speeds_kmh)}
    duration_index = {v: i for i, v in enumerate(settings.durations_s)}
    for s in summaries:
        if s.cell.road == road:
            value = getattr(s, stat)
            out[speed_index[s.cell.speed_kmh], duration_index[s.cell.duration_s]] = value
    return out


def _heatmap(
    fig: Figure, ax, settings: StudySettings, values: np.ndarray, label: str, fmt: str,
    norm: colors.Normalize, cmap: str,
) -> None:
    """One speed x duration panel with every value printed in its cell and a colorbar."""
    image = ax.imshow(np.ma.masked_invalid(values), origin="lower", aspect="auto", cmap=cmap, norm=norm)
    ax.set_xticks(range(len(settings.durations_s)), [f"{d:g}" for d in settings.durations_s])
    ax.set_yticks(range(len(settings.speeds_kmh)), [f"{v:g}" for v in settings.speeds_kmh])
    ax.set_xlabel("measurement time [s]")
    ax.set_ylabel("speed [km/h]")
    size = 7 if values.shape[1] <= 12 else 5
    for (i, j), v in np.ndenumerate(values):
        if np.isfinite(v):
            rgba = image.cmap(image.norm(v))
            dark = 0.299 * rgba[0] + 0.587 * rgba[1] + 0.114 * rgba[2] < 0.5
            ax.text(j, i, fmt.format(v), ha="center", va="center", fontsize=size,
                    color="white" if dark else "black", in_layout=False)
    fig.colorbar(image, ax=ax, label=label)


def _std_norm(values: np.ndarray) -> colors.Normalize:
    finite = values[np.isfinite(values) & (values > 0)]
    if finite.size and finite.max() / finite.min() > 5:
        return colors.LogNorm(finite.min(), finite.max())
    return colors.Normalize(*(finite.min(), finite.max()) if finite.size else (0, 1))


def _value_format(values: np.ndarray) -> str:
    finite = np.abs(values[np.isfinite(values)])
    top = finite.max() if finite.size else 1.0
    return "{:.0f}" if top >= 100 else "{:.1f}" if top >= 1 else "{:.3f}"


def std_heatmaps(settings: StudySettings, summaries: Sequence[CellSummary], road: str) -> Figure:
    std = grid_values(settings, summaries, road, "std")
    params = settings.car.params
    fig = Figure(figsize=(16 * len(params) / 3, 4.6), layout="constrained")
    axes = fig.subplots(1, len(params))
    for k, p in enumerate(params):
        values = std[:, :, k]
        _heatmap(fig, axes[k], settings, values, f"std of {p.symbol} [{p.unit}]",
                 _value_format(values), _std_norm(values), "viridis")
        axes[k].set_title(f"{p.label} {p.symbol}: std [{p.unit}]")
    fig.suptitle(f"Std of the estimates over {settings.trials} roads per cell — {road_label(settings, road)}")
    return fig


def bias_heatmaps(settings: StudySettings, summaries: Sequence[CellSummary], road: str) -> Figure:
    bias = grid_values(settings, summaries, road, "bias_pct")
    params = settings.car.params
    fig = Figure(figsize=(16 * len(params) / 3, 4.6), layout="constrained")
    axes = fig.subplots(1, len(params))
    for k, p in enumerate(params):
        values = bias[:, :, k]
        finite = np.abs(values[np.isfinite(values)])
        top = max(float(finite.max()) if finite.size else 1.0, 0.5)
        _heatmap(fig, axes[k], settings, values, f"bias of mean {p.symbol} [%]", "{:+.1f}",
                 colors.Normalize(-top, top), "RdBu_r")
        share = "(mean − truth) / half track" if p.of_half_track else "(mean / truth − 1)"
        axes[k].set_title(f"{p.label} {p.symbol}: {share} [%]")
    fig.suptitle(f"Bias of the mean estimate vs truth — {road_label(settings, road)}")
    return fig


def std_ratio_heatmaps(settings: StudySettings, summaries: Sequence[CellSummary]) -> Figure:
    laplace, iso = (grid_values(settings, summaries, road, "std") for road in ("laplace", "iso"))
    ratio = laplace / iso
    params = settings.car.params
    fig = Figure(figsize=(16 * len(params) / 3, 4.6), layout="constrained")
    axes = fig.subplots(1, len(params))
    for k, p in enumerate(params):
        values = ratio[:, :, k]
        finite = values[np.isfinite(values) & (values > 0)]
        median = float(np.median(finite)) if finite.size else float("nan")
        _heatmap(fig, axes[k], settings, values, "std Laplace / std ISO [–]", "{:.1f}",
                 _std_norm(values), "magma")
        axes[k].set_title(f"{p.label} {p.symbol}: median ratio {median:.1f}")
    fig.suptitle(f"Std on the Laplace road (ν = {settings.laplace_nu:g}) over std on the ISO road "
                 f"({settings.amplitudes} amplitudes); the thesis reports ≈ 5")
    return fig


def std_lines(settings: StudySettings, summaries: Sequence[CellSummary], road: str) -> Figure:
    """Std vs measurement time (a line per speed) and vs speed (a line per time)."""
    std = grid_values(settings, summaries, road, "std")
    params = settings.car.params
    fig = Figure(figsize=(12, 10 * len(params) / 3), layout="constrained")
    axes = fig.subplots(len(params), 2)
    speeds = np.array(settings.speeds_kmh)
    durations = np.array(settings.durations_s)
    speed_colors = matplotlib.colormaps["viridis"](np.linspace(0, 0.9, len(speeds)))
    picks = np.linspace(0, len(durations) - 1, min(6, len(durations))).round().astype(int)
    shown = durations[np.unique(picks)]
    time_colors = matplotlib.colormaps["plasma"](np.linspace(0, 0.85, len(shown)))
    for k, p in enumerate(params):
        left, right = axes[k]
        for i, speed in enumerate(speeds):
            left.plot(durations, std[i, :, k], "o-", ms=3, color=speed_colors[i], label=f"{speed:g} km/h")
        for color, duration in zip(time_colors, shown, strict=True):
            j = int(np.flatnonzero(durations == duration)[0])
            right.plot(speeds, std[:, j, k], "o-", ms=3, color=color, label=f"{duration:g} s")
        ylabel = f"std of {p.symbol} [{p.unit}]"
        left.set(xlabel="measurement time [s]", ylabel=ylabel,
                 title=f"{p.label}: std vs measurement time")
        right.set(xlabel="speed [km/h]", ylabel=ylabel, title=f"{p.label}: std vs speed")
        for ax in (left, right):
            if np.nanmax(std[:, :, k]) > 5 * np.nanmin(std[:, :, k]):
                ax.set_yscale("log")
            ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(title="speed", fontsize=7, ncols=2)
    axes[0, 1].legend(title="measurement time", fontsize=7, ncols=2)
    fig.suptitle(f"Std of the estimates over {settings.trials} roads — {road_label(settings, road)}")
    return fig


def precision_lines(settings: StudySettings, summaries: Sequence[CellSummary], road: str) -> Figure:
    """Std as a share of the truth vs measurement time, a line per speed, the shortest drive
    for 1 % starred; below, when the method publishes a std, its 95 % coverage per cell."""
    from scipy.stats import binom

    params = settings.car.params
    rel = grid_values(settings, summaries, road, "std") / np.abs(settings.reference()) * 100.0
    coverage = any(s.with_std for s in summaries if s.cell.road == road)
    fig = Figure(figsize=(15 * len(params) / 3, 8.4 if coverage else 4.6), layout="constrained")
    axes = np.atleast_2d(fig.subplots(2 if coverage else 1, len(params), sharex=True))
    speeds, durations = settings.speeds_kmh, np.array(settings.durations_s)
    palette = matplotlib.colormaps["viridis"](np.linspace(0, 0.9, len(speeds)))
    drives = {d.speed_kmh: d.duration_s for d in shortest_drives(settings, summaries) if d.road == road}
    covered = {stat: 100.0 * grid_values(settings, summaries, road, stat)
               for stat in ("coverage_95", "coverage_95_statistical")}
    lo, hi = (100.0 * binom.ppf(q, settings.trials, 0.95) / settings.trials for q in (0.025, 0.975))
    floor = float(np.nanmin(np.append(np.concatenate([c.ravel() for c in covered.values()]), lo)))
    for k, p in enumerate(params):
        top = axes[0, k]
        for i, (speed, color) in enumerate(zip(speeds, palette, strict=True)):
            top.plot(durations, rel[i, :, k], "o-", ms=3, color=color, label=f"{speed:g} km/h")
            best = drives.get(speed, (None,) * len(params))[k]
            if best is not None:
                j = int(np.flatnonzero(durations == best)[0])
                top.plot(best, rel[i, j, k], "*", ms=13, color=color, mec="black", mew=0.6)
        top.axhline(TARGET_PCT / TARGET_SIGMAS, color="black", ls="--", lw=1,
                    label=f"{TARGET_SIGMAS:g}σ = {TARGET_PCT:g} %")
        finite = rel[:, :, k][np.isfinite(rel[:, :, k]) & (rel[:, :, k] > 0)]
        if finite.size and finite.max() > 5 * finite.min():
            top.set_yscale("log")
            top.yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))  # 0.1, 1, 10
            top.yaxis.set_minor_formatter(ticker.FuncFormatter(_minor_label))  # 0.2, 0.3, 0.5, 2
        top.set(ylabel=f"std of {p.symbol} [% of {p.relative_to}]", title=f"{p.label} {p.symbol}: std")
        top.grid(True, which="both", alpha=0.3)
        if coverage:
            bottom = axes[1, k]
            bottom.axhspan(lo, hi, color="grey", alpha=0.15,
                           label=f"95 % range for an honest std ({settings.trials} trials)")
            bottom.axhline(95.0, color="black", lw=0.8)
            for i, color in enumerate(palette):
                bottom.plot(durations, covered["coverage_95"][i, :, k], "o-", ms=3, color=color)
                bottom.plot(durations, covered["coverage_95_statistical"][i, :, k], "s--", ms=4, color=color,
                            mfc="none")
            bottom.plot([], [], "k-", label="published std")
            bottom.plot([], [], "k--", label="statistical part")
            bottom.set(ylabel="coverage of ±1.96 std [%]", ylim=(floor - 5.0, 102.0),
                       title=f"{p.label} {p.symbol}: coverage")
            bottom.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("measurement time [s]")
    axes[0, 0].plot([], [], "*", ms=10, color="grey", mec="black", mew=0.6,
                    label=f"shortest drive for {TARGET_PCT:g} %")
    axes[0, 0].legend(title="speed", fontsize=7, ncols=2)
    if coverage:
        axes[1, 0].legend(fontsize=7, loc="lower right")
    fig.suptitle(f"Std of the estimates over {settings.trials} roads per cell as a share of the truth"
                 + (" and the share of trials whose estimate ± 1.96 std holds the truth" if coverage else "")
                 + f"\n{road_label(settings, road)}, method {settings.method}")
    return fig


def _minor_label(value: float, _: int) -> str:
    """A log axis' minor tick as a plain number at 2, 3 and 5 times a power of ten, else none."""
    return f"{value:g}" if value > 0 and f"{value:.0e}"[0] in "235" else ""


def _cell_params(settings: StudySettings, rows: Sequence[TrialRow], cell: Cell) -> np.ndarray:
    params = [r.params for r in rows if r.cell == cell and r.params is not None]
    return np.array(params, dtype=float).reshape(-1, len(settings.car.params))


def histograms(settings: StudySettings, rows: Sequence[TrialRow], cells: Sequence[Cell]) -> Figure:
    """Estimates of one speed and time, a row per road (Figs 5-7 to 5-9, 5-16 to 5-18)."""
    truth, names = settings.truth(), settings.car.params
    fig = Figure(figsize=(14 * len(names) / 3, 3.4 * len(cells) + 0.6), layout="constrained")
    axes = np.atleast_2d(fig.subplots(len(cells), len(names)))
    for r, cell in enumerate(cells):
        params = _cell_params(settings, rows, cell)
        for k, p in enumerate(names):
            ax = axes[r, k]
            if len(params):
                ax.hist(params[:, k], bins=min(25, max(5, len(params) // 4)), color="tab:blue", alpha=0.8)
                mean, std = params[:, k].mean(), params[:, k].std(ddof=1) if len(params) > 1 else 0.0
                ax.axvline(mean, color="tab:red", label=f"mean {mean:.4g} (std {std:.3g})")
            ax.axvline(truth[k], color="black", ls="--", label=f"truth {truth[k]:g}")
            ax.set(xlabel=f"{p.label} {p.symbol} [{p.unit}]", ylabel="trials",
                   title=f"{cell.road}: {p.label}")
            ax.legend(fontsize=7)
    cell = cells[0]
    fig.suptitle(f"Estimates over {settings.trials} roads at {cell.speed_kmh:g} km/h, {cell.duration_s:g} s "
                 f"({settings.amplitudes} amplitudes)")
    return fig


def error_boxplot(settings: StudySettings, rows: Sequence[TrialRow], cells: Sequence[Cell]) -> Figure:
    """Relative errors of one speed and time, a box per road (Figs 5-10, 5-19)."""
    car, truth, reference = settings.car, settings.truth(), settings.reference()
    fig = Figure(figsize=(12 * len(car.params) / 3, 4.4), layout="constrained")
    axes = fig.subplots(1, len(car.params))
    errors_pct = [car.relative_pct(_cell_params(settings, rows, c), truth, reference) for c in cells]
    for k, p in enumerate(car.params):
        ax = axes[k]
        errors = [e[:, k] for e in errors_pct]
        ax.boxplot(errors, tick_labels=[c.road for c in cells])
        for level in (-6.0, 6.0):
            ax.axhline(level, color="grey", ls=":", lw=1)
        ax.axhline(0.0, color="black", lw=0.8)
        of = " of half track" if p.of_half_track else ""
        ax.set(ylabel=f"error of {p.symbol} [%{of}]", xlabel="road", title=f"{p.label} {p.symbol}")
        ax.grid(True, axis="y", alpha=0.3)
    cell = cells[0]
    fig.suptitle(f"Errors (estimate / truth − 1) at {cell.speed_kmh:g} km/h, {cell.duration_s:g} s, "
                 f"{settings.trials} roads; dotted: ±6 %")
    return fig


def correlation_overlay(settings: StudySettings, correlations: Sequence[CellCorrelations]) -> Figure:
    """Every trial's normalised autocorrelation, a row per road, a column per accelerometer."""
    channels = settings.car.channels
    fig = Figure(figsize=(6.5 * len(channels), 3.6 * len(correlations) + 0.6), layout="constrained")
    axes = np.atleast_2d(fig.subplots(len(correlations), len(channels), sharey=True))
    for r, corr in enumerate(correlations):
        first, last = corr.fit_lags_s
        for c, (side, sub) in enumerate(channels):
            ax = axes[r, c]
            ax.plot(corr.lag_s, corr.acf[:, :, c].T, color="tab:blue", lw=0.5, alpha=0.25)
            ax.plot(corr.lag_s, corr.acf[:, :, c].mean(axis=0), color="black", lw=1.2, label="mean")
            ax.axvspan(0, first, color="tab:red", alpha=0.08, label=f"skipped: lag < {first:.2f} s")
            ax.axvspan(first, last, color="tab:green", alpha=0.08, label="lags the estimator uses")
            ax.set(xlabel="lag τ [s]", ylabel=f"R_{sub}{sub}(τ) / R_{sub}{sub}(0) [–]",
                   title=f"{corr.cell.road}: {side} acceleration, {len(corr.acf)} roads")
            ax.set_xlim(0, corr.lag_s[-1])
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, loc="upper right")
    cell = correlations[0].cell
    fig.suptitle(f"Autocorrelation of the body accelerations at {cell.speed_kmh:g} km/h, "
                 f"{cell.duration_s:g} s ({settings.amplitudes} amplitudes)")
    return fig


def failure_heatmaps(settings: StudySettings, summaries: Sequence[CellSummary]) -> Figure:
    fig = Figure(figsize=(6.5 * len(settings.roads), 4.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(settings.roads)))
    for ax, road in zip(axes, settings.roads, strict=True):
        failed = grid_values(settings, summaries, road, "failures")
        _heatmap(fig, ax, settings, failed, "failed trials", "{:.0f}",
                 colors.Normalize(0, max(1.0, float(np.nanmax(failed)))), "Reds")
        ax.set_title(road_label(settings, road))
    fig.suptitle(f"Failed identifications per cell (of {settings.trials} trials)")
    return fig
