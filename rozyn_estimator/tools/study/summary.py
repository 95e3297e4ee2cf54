"""Per-cell statistics of a study's trials and their tables (``summary.csv``, ``summary.md``'s).

The statistics are those of ``rozyn trial`` (:func:`rozyn_estimator.tools.trial.summarise`)
plus a robust spread (interquartile range / 1.349) and, where the method publishes a
standard deviation with each estimate, how honest it is: its rms over the trials and its
95 % coverage (the share of the trials whose ±1.96 std interval holds the truth), for the
published std and for its statistical part alone.

Relative statistics (bias, share within 6 %) are of the truth; the full car's lateral CoG's,
whose truth is often 0, of the half track (:mod:`~rozyn_estimator.tools.cars`).
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rozyn_estimator.tools.cars import HALF, Car
from rozyn_estimator.tools.study.results import Params, TrialRow
from rozyn_estimator.tools.study.settings import Cell, StudySettings, fmt_value
from rozyn_estimator.tools.trial.summary import summarise

Z_95 = 1.96  # the two-sided 95 % quantile of the normal distribution
SUMMARY_STATS = ("mean", "std", "bias_pct", "within_6pct", "robust_std", "reported_std", "coverage_95",
                 "reported_std_statistical", "coverage_95_statistical")


def summary_columns(model: Car) -> tuple[str, ...]:
    """The header of ``summary.csv``: the cell, then every statistic per parameter."""
    return ("road", "speed_kmh", "duration_s", "trials", "failures", "with_std",
            *(f"{p}_{stat}" for p in model.names for stat in SUMMARY_STATS))


SUMMARY_COLUMNS = summary_columns(HALF)


@dataclass(frozen=True)
class CellSummary:
    """Statistics of one cell's trials, per parameter in the model's order.

    The published-std statistics are over the successful trials that carry a std
    (``with_std`` of them); NaN when none does (e.g. Rozyn's pipeline in a study, whose
    per-trial covariance is off).
    """

    cell: Cell
    n: int
    failures: int
    truth: np.ndarray
    mean: np.ndarray
    std: np.ndarray  # sample std (ddof = 1) over the successful trials: the spread
    bias_pct: np.ndarray
    within_6pct: np.ndarray  # share of successful trials within 6 % of the truth
    robust_std: np.ndarray  # interquartile range / 1.349: the std a normal spread would have
    with_std: int  # successful trials with a published std
    reported_std: np.ndarray  # rms of the published std
    coverage_95: np.ndarray  # share with |estimate - truth| <= 1.96 published std
    reported_std_statistical: np.ndarray  # rms of its statistical part
    coverage_95_statistical: np.ndarray  # the same with the statistical part
    reference: np.ndarray | None = None  # what bias and precision are shares of; None: the truth

    @property
    def scale(self) -> np.ndarray:
        """What the relative statistics are a share of: the truth (the lateral CoG's: the half track)."""
        return self.truth if self.reference is None else self.reference


def summarise_cells(settings: StudySettings, rows: Iterable[TrialRow]) -> list[CellSummary]:
    """One summary per cell of the grid that has results, in grid order.

    Uses the same statistics as ``rozyn trial`` (:func:`rozyn_estimator.tools.trial.summarise`);
    a parameter measured against the half track has its bias and share within 6 % of that.
    """
    truth, reference, car = settings.truth(), settings.reference(), settings.car
    by_cell: dict[Cell, list[TrialRow]] = {}
    for row in rows:
        by_cell.setdefault(row.cell, []).append(row)
    out = []
    for cell in settings.cells():
        if cell not in by_cell:
            continue
        with np.errstate(divide="ignore", invalid="ignore"):  # a zero truth: its share is replaced below
            s = summarise(r.to_trial_result(truth) for r in by_cell[cell])
        ok = [r for r in by_cell[cell] if r.status == "ok" and r.params is not None]
        bias_pct, within = s.bias_pct, s.within_6pct
        if car.scaled.any() and ok:
            errors = car.relative_pct(np.array([r.params for r in ok]), truth, reference)
            bias_pct = np.where(car.scaled, car.relative_pct(s.mean, truth, reference), bias_pct)
            within = np.where(car.scaled, np.mean(np.abs(errors) <= 6.0, axis=0), within)
        published = [r for r in ok if r.std is not None]
        statistical = [r for r in ok if r.std_statistical is not None]
        out.append(CellSummary(
            cell, s.n, s.failures, truth, s.mean, s.std, bias_pct, within,
            _robust_std([r.params for r in ok], len(truth)), len(published),
            *_honesty([r.params for r in published], [r.std for r in published], truth),
            *_honesty([r.params for r in statistical], [r.std_statistical for r in statistical], truth),
            reference,
        ))
    return out


def _robust_std(params: Sequence[Params | None], k: int) -> np.ndarray:
    if len(params) < 2:
        return np.full(k, np.nan)
    q1, q3 = np.percentile(np.array(params, dtype=float), [25, 75], axis=0)
    return (q3 - q1) / 1.349


def _honesty(
    params: Sequence[Params | None], stds: Sequence[Params | None], truth: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(rms of the std, share of the trials whose ±1.96 std interval holds the truth)."""
    if not params:
        return np.full(len(truth), np.nan), np.full(len(truth), np.nan)
    p, std = np.array(params, dtype=float), np.array(stds, dtype=float)
    return np.sqrt(np.mean(std**2, axis=0)), np.mean(np.abs(p - truth) <= Z_95 * std, axis=0)


def study_title(settings: StudySettings) -> str:
    """The title of ``summary.md``: the road, the method and the trials per cell."""
    noise = f", sensor noise {settings.noise_std_mps2:g} m/s²" if settings.noise_std_mps2 else ""
    if settings.noise_fraction:
        noise += f", sensor noise {settings.noise_fraction:.0%} of each channel's rms"
    car = "full car (two road tracks, four corners), " if settings.model == "full" else ""
    return (f"Study: {car}ISO 8608 class {settings.road_class} base road, {settings.amplitudes} amplitudes"
            f"{noise}, method {settings.method}, {settings.trials} trials per cell")


def write_summary_csv(summaries: Sequence[CellSummary], path: Path, model: Car = HALF) -> None:
    """``summary.csv``: the per-cell statistics at full precision."""
    with path.open("w", newline="") as f:
        out = csv.writer(f, lineterminator="\n")
        out.writerow(summary_columns(model))
        for s in summaries:
            stats = [getattr(s, stat)[i] for i in range(len(model.params)) for stat in SUMMARY_STATS]
            out.writerow([s.cell.road, fmt_value(s.cell.speed_kmh), fmt_value(s.cell.duration_s), s.n,
                          s.failures, s.with_std, *(repr(float(v)) for v in stats)])


def summary_markdown(settings: StudySettings, summaries: Sequence[CellSummary]) -> list[str]:
    """The lines of ``summary.md``'s title, legend and tables: one per parameter, rounded."""
    stds = any(s.with_std for s in summaries)
    truths, scales = settings.truth(), settings.reference()
    lines = [f"# {study_title(settings)}", "", _legend(stds, settings.car)]
    for k, p in enumerate(settings.car.params):
        unit, value_fmt, spread_fmt = p.unit, p.value_fmt, p.spread_fmt
        title = f"## {p.label} {p.symbol} [{unit}], truth {truths[k]:g}"
        bias = "bias [%]"
        if p.of_half_track:
            title += f"; bias in % of the half track ({scales[k]:g} m)"
            bias = "bias [% of half track]"
        head = (f"| road | speed [km/h] | time [s] | trials | failures | mean [{unit}] | std [{unit}] "
                f"| {bias} |")
        if stds:
            head += (f" with std | published std [{unit}] | coverage 95 % | statistical std [{unit}] "
                     f"| coverage 95 % (statistical) |")
        lines += ["", title, "", head, "|" + "---|" * (head.count("|") - 1)]
        for s in summaries:
            cells = [s.cell.road, fmt_value(s.cell.speed_kmh), fmt_value(s.cell.duration_s), str(s.n),
                     str(s.failures), _num(value_fmt, s.mean[k]), _num(spread_fmt, s.std[k]),
                     _num("{:+.2f}", s.bias_pct[k])]
            if stds:
                cells += [str(s.with_std), _num(spread_fmt, s.reported_std[k]), _pct(s.coverage_95[k]),
                          _num(spread_fmt, s.reported_std_statistical[k]), _pct(s.coverage_95_statistical[k])]
            lines.append("| " + " | ".join(cells) + " |")
    return lines


def _legend(stds: bool, model: Car) -> str:
    text = ("std: the spread of the successful trials' estimates (sample std); bias: mean / truth − 1; "
            "failures: trials without an estimate.")
    scaled = [p.symbol for p in model.params if p.of_half_track]
    if scaled:
        text += (f" The bias of {', '.join(scaled)} (whose truth may be 0): (mean − truth) / half track, "
                 "the half track being half the mean of the front and rear tracks.")
    if stds:
        text += (" Published std: the rms of the std published with each estimate (the data's part and "
                 "the tolerances' together); statistical std: the data's part alone; with std: the "
                 "successful trials that carry one. Coverage 95 %: the share of those whose estimate "
                 "± 1.96 std holds the truth (an honest std: about 95 %; the simulated vehicle is "
                 "the assumed one, so the tolerances' part is not realised here and the published "
                 "coverage may exceed it).")
    else:
        text += " The method publishes no std with its estimates here: no coverage."
    return text


def _num(fmt: str, value: float) -> str:
    return "–" if not np.isfinite(value) else fmt.format(value)


def _pct(share: float) -> str:
    return "–" if not np.isfinite(share) else f"{100.0 * share:.0f} %"
