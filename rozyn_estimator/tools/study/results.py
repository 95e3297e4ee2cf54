"""Trial rows and the results file: one :class:`TrialRow` per line of ``results.csv``.

The parent process appends each finished chunk to the file (:class:`ResultsWriter`), so
an interrupted study keeps what it computed; a line cut short by the interruption is
skipped on reading, and a finished study's file is rewritten in grid order.

Each row carries the estimate and, when the method publishes one, its standard deviation
twice: ``<param>_std``, the published one (the square root of the covariance's diagonal:
the data's part and the tolerances' propagated together) and ``<param>_std_statistical``,
the data's part alone (the budget's statistical covariance; the covariance itself when
there is no budget). Files written before these columns existed (:data:`LEGACY_COLUMNS`)
are read as rows without a std.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PARAM_NAMES, Estimate
from rozyn_estimator.tools.study.settings import Cell, StudySettings, fmt_value
from rozyn_estimator.tools.trial import TrialResult

MODE_COLUMNS = ("mode1_freq_hz", "mode1_damping", "mode2_freq_hz", "mode2_damping")
STD_COLUMNS = tuple(f"{p}_std" for p in PARAM_NAMES)  # the published std
STATISTICAL_STD_COLUMNS = tuple(f"{p}_std_statistical" for p in PARAM_NAMES)  # the data's part
_KEY_COLUMNS = ("road", "speed_kmh", "duration_s", "trial", "seed", "status", "stage")
COLUMNS = (*_KEY_COLUMNS, *PARAM_NAMES, *STD_COLUMNS, *STATISTICAL_STD_COLUMNS, *MODE_COLUMNS, "reason")
LEGACY_COLUMNS = (*_KEY_COLUMNS, *PARAM_NAMES, *MODE_COLUMNS, "reason")  # before the std columns

Params = tuple[float, float, float]  # in PARAM_NAMES order
Modes = tuple[float, float, float, float]  # f1 [Hz], zeta1, f2 [Hz], zeta2


@dataclass(frozen=True)
class TrialRow:
    """One line of ``results.csv``."""

    cell: Cell
    trial: int
    seed: int
    status: str  # "ok", "failed" (no honest estimate) or "error" (the trial raised an exception)
    params: Params | None
    modes: Modes | None
    reason: str = ""
    stage: str = "rozyn"  # the estimator stage whose numbers these are
    std: Params | None = None  # the published std (sqrt diag of the covariance); None: none published
    std_statistical: Params | None = None  # its statistical part (the data's)

    @property
    def key(self) -> tuple[str, float, float, int]:
        return (self.cell.road, self.cell.speed_kmh, self.cell.duration_s, self.trial)

    @classmethod
    def from_result(cls, cell: Cell, trial: int, result: TrialResult) -> TrialRow:
        est = result.estimate
        modes: Modes | None = None
        if len(est.modes) >= 2:
            first, second = est.modes[:2]
            modes = (float(first.freq_hz), float(first.damping_ratio),
                     float(second.freq_hz), float(second.damping_ratio))
        return cls(cell, trial, result.seed, est.status, _params(est.params), modes, est.reason,
                   getattr(est, "stage", "rozyn"), _params(est.std), _params(est.statistical_std))

    def to_csv(self) -> list[str]:
        def num(values: Sequence[float] | None, n: int) -> list[str]:
            return [""] * n if values is None else [repr(float(v)) for v in values]

        c = self.cell
        return [c.road, fmt_value(c.speed_kmh), fmt_value(c.duration_s), str(self.trial), str(self.seed),
                self.status, self.stage, *num(self.params, 3), *num(self.std, 3),
                *num(self.std_statistical, 3), *num(self.modes, 4), self.reason]

    @classmethod
    def from_csv(cls, record: dict[str, str]) -> TrialRow:
        """A row from a CSV record (of :data:`COLUMNS`, or :data:`LEGACY_COLUMNS`: no std)."""
        def nums(names: Sequence[str]) -> list[float] | None:
            text = [record.get(n, "") for n in names]
            return None if any(t == "" for t in text) else [float(t) for t in text]

        cell = Cell(record["road"], float(record["speed_kmh"]), float(record["duration_s"]))
        m = nums(MODE_COLUMNS)
        modes = None if m is None else (m[0], m[1], m[2], m[3])
        return cls(cell, int(record["trial"]), int(record["seed"]), record["status"],
                   _params(nums(PARAM_NAMES)), modes, record["reason"], record["stage"],
                   _params(nums(STD_COLUMNS)), _params(nums(STATISTICAL_STD_COLUMNS)))

    def to_trial_result(self, truth: np.ndarray) -> TrialResult:
        params = None if self.params is None else np.array(self.params)
        est = Estimate(status=self.status, reason=self.reason, params=params)
        return TrialResult(seed=self.seed, estimate=est, truth=truth, sim_ms=float("nan"))


def _params(values: Sequence[float] | np.ndarray | None) -> Params | None:
    """Three numbers in PARAM_NAMES order as floats (None stays None)."""
    if values is None:
        return None
    first, second, third = (float(v) for v in values)
    return (first, second, third)


def read_results(path: Path) -> list[TrialRow]:
    """The complete rows of a results file (a line cut short by an interruption is skipped)."""
    rows, _ = scan_results(path)
    return rows


def scan_results(path: Path) -> tuple[list[TrialRow], bool]:
    """(rows, clean): ``clean`` is False when rows cannot be appended to the file as it is:
    it ends in a partial line, holds a line that is not a row, or has the legacy header."""
    with path.open(newline="") as f:
        text = f.read()
    clean = text == "" or text.endswith("\n")
    lines = text.splitlines(keepends=True)
    if not clean:
        lines = lines[:-1]
    reader = csv.DictReader(lines)
    header = tuple(reader.fieldnames or ())
    if header not in (COLUMNS, LEGACY_COLUMNS):
        raise ConfigError(f"{path}: not a study results file (header {reader.fieldnames})")
    clean = clean and header == COLUMNS
    rows = []
    for record in reader:
        try:
            rows.append(TrialRow.from_csv(record))
        except (ValueError, TypeError, KeyError):
            clean = False
    return rows, clean


class ResultsWriter:
    """Appends trial rows to ``results.csv``, flushed after each chunk."""

    def __init__(self, path: Path, rows: Sequence[TrialRow] = (), rewrite: bool = False) -> None:
        self.path = path
        if rewrite or not path.exists():
            write_results(path, rows)
        self._file = path.open("a", newline="")
        self._csv = csv.writer(self._file, lineterminator="\n")

    def write(self, rows: Iterable[TrialRow]) -> None:
        self._csv.writerows(r.to_csv() for r in rows)
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def write_results(path: Path, rows: Iterable[TrialRow]) -> None:
    """Write a whole results file (atomically: a new file, then renamed over the old one)."""
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        out = csv.writer(f, lineterminator="\n")
        out.writerow(COLUMNS)
        out.writerows(r.to_csv() for r in rows)
    os.replace(tmp, path)


def sort_rows(settings: StudySettings, rows: Iterable[TrialRow]) -> list[TrialRow]:
    """Rows in grid order (road, speed, duration as in the settings, then trial)."""
    order = {cell: i for i, cell in enumerate(settings.cells())}
    return sorted(rows, key=lambda r: (order.get(r.cell, len(order)), r.cell, r.trial))
