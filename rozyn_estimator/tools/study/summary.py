"""Per-cell statistics of a study's trials and the summary tables (``summary.csv``/``.md``).

The statistics are those of ``rozyn trial`` (:func:`rozyn_estimator.tools.trial.summarise`)
plus a robust spread (interquartile range / 1.349).
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rozyn_estimator.method import PARAM_NAMES
from rozyn_estimator.tools.study.results import Params, TrialRow
from rozyn_estimator.tools.study.settings import Cell, StudySettings, fmt_value
from rozyn_estimator.tools.trial import summarise

SUMMARY_STATS = ("mean", "std", "bias_pct", "within_6pct", "robust_std")
SUMMARY_COLUMNS = (
    "road", "speed_kmh", "duration_s", "trials", "failures",
    *(f"{p}_{stat}" for p in PARAM_NAMES for stat in SUMMARY_STATS),
)


@dataclass(frozen=True)
class CellSummary:
    """Statistics of one cell's trials, per parameter in PARAM_NAMES order."""

    cell: Cell
    n: int
    failures: int
    truth: np.ndarray
    mean: np.ndarray
    std: np.ndarray  # sample std (ddof = 1) over the successful trials
    bias_pct: np.ndarray
    within_6pct: np.ndarray  # share of successful trials within 6 % of the truth
    robust_std: np.ndarray  # interquartile range / 1.349: the std a normal spread would have


def summarise_cells(settings: StudySettings, rows: Iterable[TrialRow]) -> list[CellSummary]:
    """One summary per cell of the grid that has results, in grid order.

    Uses the same statistics as ``rozyn trial`` (:func:`rozyn_estimator.tools.trial.summarise`).
    """
    truth = np.array([settings.vehicle.sprung_mass_kg, settings.vehicle.pitch_inertia_kgm2,
                      settings.vehicle.cog_from_front_axle_m])
    by_cell: dict[Cell, list[TrialRow]] = {}
    for row in rows:
        by_cell.setdefault(row.cell, []).append(row)
    out = []
    for cell in settings.cells():
        if cell not in by_cell:
            continue
        s = summarise(r.to_trial_result(truth) for r in by_cell[cell])
        out.append(CellSummary(cell, s.n, s.failures, truth, s.mean, s.std, s.bias_pct, s.within_6pct,
                               _robust_std([r.params for r in by_cell[cell] if r.status == "ok"])))
    return out


def _robust_std(params: Sequence[Params | None]) -> np.ndarray:
    if len(params) < 2:
        return np.full(3, np.nan)
    q1, q3 = np.percentile(np.array(params, dtype=float), [25, 75], axis=0)
    return (q3 - q1) / 1.349


def study_title(settings: StudySettings) -> str:
    """The title of ``summary.md``: the road, the method and the trials per cell."""
    noise = f", sensor noise {settings.noise_std_mps2:g} m/s²" if settings.noise_std_mps2 else ""
    return (f"Study: ISO 8608 class {settings.road_class} base road, {settings.amplitudes} amplitudes"
            f"{noise}, method {settings.method}, {settings.trials} trials per cell")


def write_summary(summaries: Sequence[CellSummary], csv_path: Path, md_path: Path, title: str) -> None:
    """The per-cell table as CSV (full precision) and Markdown (rounded, for reading)."""
    with csv_path.open("w", newline="") as f:
        out = csv.writer(f, lineterminator="\n")
        out.writerow(SUMMARY_COLUMNS)
        for s in summaries:
            stats = [getattr(s, stat)[i] for i in range(3) for stat in SUMMARY_STATS]
            out.writerow([s.cell.road, fmt_value(s.cell.speed_kmh), fmt_value(s.cell.duration_s), s.n,
                          s.failures, *(repr(float(v)) for v in stats)])
    md_path.write_text(summary_markdown(summaries, title))


def summary_markdown(summaries: Sequence[CellSummary], title: str) -> str:
    head = ("| road | speed [km/h] | time [s] | trials | failures | mean m [kg] | std m [kg] | bias m [%] "
            "| mean I_yy [kg m²] | std I_yy [kg m²] | bias I_yy [%] | mean l_f [m] | std l_f [m] "
            "| bias l_f [%] |")
    lines = [f"# {title}", "", head, "|" + "---|" * (head.count("|") - 1)]
    for s in summaries:
        cells = [s.cell.road, fmt_value(s.cell.speed_kmh), fmt_value(s.cell.duration_s), str(s.n),
                 str(s.failures)]
        for i, (mean_fmt, std_fmt) in enumerate((("{:.1f}", "{:.2f}"), ("{:.1f}", "{:.2f}"),
                                                   ("{:.4f}", "{:.4f}"))):
            cells += [_num(mean_fmt, s.mean[i]), _num(std_fmt, s.std[i]), _num("{:+.2f}", s.bias_pct[i])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _num(fmt: str, value: float) -> str:
    return "–" if not np.isfinite(value) else fmt.format(value)
