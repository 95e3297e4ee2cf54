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

The columns follow the study's model (:func:`columns`): the half car's three parameters and
two modes (:data:`COLUMNS`), or the full car's five parameters and three modes
(:data:`FULL_COLUMNS`).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import Estimate
from rozyn_estimator.tools.cars import CARS, FULL, HALF, Car
from rozyn_estimator.tools.study.settings import Cell, StudySettings, fmt_value
from rozyn_estimator.tools.trial.run import TrialResult

_KEY_COLUMNS = ("road", "speed_kmh", "duration_s", "trial", "seed", "status", "stage")


def mode_columns(model: Car) -> tuple[str, ...]:
    """``mode1_freq_hz``, ``mode1_damping``, … for the model's modes."""
    return tuple(f"mode{k}_{q}" for k in range(1, model.n_modes + 1) for q in ("freq_hz", "damping"))


def columns(model: Car) -> tuple[str, ...]:
    """The header of a results file: the estimate, its published std (``<param>_std``) and the
    std's statistical part (``<param>_std_statistical``) per parameter, the modes, the reason."""
    names = model.names
    return (*_KEY_COLUMNS, *names, *(f"{p}_std" for p in names), *(f"{p}_std_statistical" for p in names),
            *mode_columns(model), "reason")


COLUMNS = columns(HALF)
FULL_COLUMNS = columns(FULL)
LEGACY_COLUMNS = (*_KEY_COLUMNS, *HALF.names, *mode_columns(HALF), "reason")  # before the std columns
_HEADERS = {COLUMNS: HALF, FULL_COLUMNS: FULL, LEGACY_COLUMNS: HALF}

Params = tuple[float, ...]  # in the model's parameter order
Modes = tuple[float, ...]  # f1 [Hz], zeta1, f2 [Hz], zeta2 (, f3, zeta3)


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
        """The row of a half-car trial (two modes) or a full-car one (three)."""
        est = result.estimate
        n_modes = CARS[result.model].n_modes
        modes: Modes | None = None
        if len(est.modes) >= n_modes:
            modes = tuple(float(x) for md in est.modes[:n_modes] for x in (md.freq_hz, md.damping_ratio))
        return cls(cell, trial, result.seed, est.status, _params(est.params), modes, est.reason,
                   est.stage, _params(est.std), _params(est.statistical_std))

    def to_csv(self, model: Car = HALF) -> list[str]:
        def num(values: Sequence[float] | None, n: int) -> list[str]:
            return [""] * n if values is None else [repr(float(v)) for v in values]

        c, k = self.cell, len(model.params)
        return [c.road, fmt_value(c.speed_kmh), fmt_value(c.duration_s), str(self.trial), str(self.seed),
                self.status, self.stage, *num(self.params, k), *num(self.std, k),
                *num(self.std_statistical, k), *num(self.modes, 2 * model.n_modes), self.reason]

    @classmethod
    def from_csv(cls, record: dict[str, str], model: Car = HALF) -> TrialRow:
        """A row from a CSV record (of :func:`columns`, or :data:`LEGACY_COLUMNS`: no std)."""
        def nums(names: Sequence[str]) -> tuple[float, ...] | None:
            text = [record.get(n, "") for n in names]
            return None if any(t == "" for t in text) else tuple(float(t) for t in text)

        cell = Cell(record["road"], float(record["speed_kmh"]), float(record["duration_s"]))
        names = model.names
        return cls(cell, int(record["trial"]), int(record["seed"]), record["status"],
                   nums(names), nums(mode_columns(model)), record["reason"], record["stage"],
                   nums([f"{p}_std" for p in names]), nums([f"{p}_std_statistical" for p in names]))

    def to_trial_result(self, truth: np.ndarray) -> TrialResult:
        params = None if self.params is None else np.array(self.params)
        est = Estimate(status=self.status, reason=self.reason, params=params)
        return TrialResult(seed=self.seed, estimate=est, truth=truth, sim_ms=float("nan"))


def _params(values: Sequence[float] | np.ndarray | None) -> Params | None:
    """The parameters as floats (None stays None)."""
    return None if values is None else tuple(float(v) for v in values)


def read_results(path: Path, model: Car | None = None) -> list[TrialRow]:
    """The complete rows of a results file (a line cut short by an interruption is skipped)."""
    rows, _ = scan_results(path, model)
    return rows


def scan_results(path: Path, model: Car | None = None) -> tuple[list[TrialRow], bool]:
    """(rows, clean): ``clean`` is False when rows cannot be appended to the file as it is:
    it ends in a partial line, holds a line that is not a row, or has the legacy header.

    Raises:
        ConfigError: not a results file, or (``model`` given) one of another model's.
    """
    with path.open(newline="") as f:
        text = f.read()
    clean = text == "" or text.endswith("\n")
    lines = text.splitlines(keepends=True)
    if not clean:
        lines = lines[:-1]
    reader = csv.DictReader(lines)
    header = tuple(reader.fieldnames or ())
    if header not in _HEADERS:
        raise ConfigError(f"{path}: not a study results file (header {reader.fieldnames})")
    found = _HEADERS[header]
    if model is not None and found is not model:
        raise ConfigError(f"{path}: results of the {found.name} car, the study's model is {model.name}")
    clean = clean and header == columns(found)
    rows = []
    for record in reader:
        try:
            rows.append(TrialRow.from_csv(record, found))
        except (ValueError, TypeError, KeyError):
            clean = False
    return rows, clean


class ResultsWriter:
    """Appends trial rows to ``results.csv``, flushed after each chunk."""

    def __init__(self, path: Path, rows: Sequence[TrialRow] = (), rewrite: bool = False,
                 model: Car = HALF) -> None:
        self.path = path
        self.model = model
        if rewrite or not path.exists():
            write_results(path, rows, model)
        self._file = path.open("a", newline="")
        self._csv = csv.writer(self._file, lineterminator="\n")

    def write(self, rows: Iterable[TrialRow]) -> None:
        self._csv.writerows(r.to_csv(self.model) for r in rows)
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def write_results(path: Path, rows: Iterable[TrialRow], model: Car = HALF) -> None:
    """Write a whole results file (atomically: a new file, then renamed over the old one)."""
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        out = csv.writer(f, lineterminator="\n")
        out.writerow(columns(model))
        out.writerows(r.to_csv(model) for r in rows)
    os.replace(tmp, path)


def sort_rows(settings: StudySettings, rows: Iterable[TrialRow]) -> list[TrialRow]:
    """Rows in grid order (road, speed, duration as in the settings, then trial)."""
    order = {cell: i for i, cell in enumerate(settings.cells())}
    return sorted(rows, key=lambda r: (order.get(r.cell, len(order)), r.cell, r.trial))
