"""A study's tables and figures from its results (``summary.csv``/``.md``, ``figures/*.png``).

``summary.md`` holds the per-cell tables (:mod:`~rozyn_estimator.tools.study.summary`) and
the shortest drive for 1 % (:mod:`~rozyn_estimator.tools.study.precision`).

The figures (:mod:`rozyn_estimator.tools.study.plots`, matplotlib) are imported only
when they are drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from rozyn_estimator.tools.study.correlations import focus_correlations
from rozyn_estimator.tools.study.precision import shortest_drive_markdown
from rozyn_estimator.tools.study.results import TrialRow
from rozyn_estimator.tools.study.settings import (
    FIGURES,
    SUMMARY_CSV,
    SUMMARY_MD,
    THESIS_CELL,
    Cell,
    StudySettings,
)
from rozyn_estimator.tools.study.summary import (
    CellSummary,
    summarise_cells,
    summary_markdown,
    write_summary_csv,
)
from rozyn_estimator.tools.study.work import ignore_sigint


def nearest_cell(settings: StudySettings, speed_kmh: float, duration_s: float) -> tuple[float, float]:
    """The grid's (speed, duration) closest to the one asked for (relative distance)."""
    speed = min(settings.speeds_kmh, key=lambda v: abs(v / speed_kmh - 1))
    duration = min(settings.durations_s, key=lambda v: abs(v / duration_s - 1))
    return speed, duration


def write_tables(out_dir: Path, settings: StudySettings, rows: Sequence[TrialRow]) -> list[CellSummary]:
    """``summary.csv`` and ``summary.md`` from the results; returns the cells' summaries."""
    summaries = summarise_cells(settings, rows)
    write_summary_csv(summaries, out_dir / SUMMARY_CSV, settings.car)
    lines = [*summary_markdown(settings, summaries), "", *shortest_drive_markdown(settings, summaries)]
    (out_dir / SUMMARY_MD).write_text("\n".join(lines) + "\n")
    return summaries


def write_outputs(
    out_dir: Path, settings: StudySettings, rows: Sequence[TrialRow],
    focus: tuple[float, float] | None = None, jobs: int = 1,
) -> list[Path]:
    """Summary tables and figures from the results, on ``jobs`` processes; returns the files written."""
    from rozyn_estimator.tools.study import plots as study_plots

    summaries = write_tables(out_dir, settings, rows)
    speed, duration = nearest_cell(settings, *(focus or THESIS_CELL))
    focus_cells = [Cell(road, speed, duration) for road in settings.roads]
    if jobs == 1:
        correlations = focus_correlations(settings, focus_cells)
        figures = study_plots.plot_study(out_dir / FIGURES, settings, summaries, rows, correlations)
    else:
        with ProcessPoolExecutor(max_workers=jobs, initializer=ignore_sigint) as pool:
            correlations = focus_correlations(settings, focus_cells, pool.map, parts=jobs)
            figures = study_plots.plot_study(out_dir / FIGURES, settings, summaries, rows, correlations,
                                             pool.map)
    return [out_dir / SUMMARY_CSV, out_dir / SUMMARY_MD, *figures]
