"""``rozyn study``: the thesis' Monte-Carlo grids (chapter 5) as one command.

Every (road, speed, measurement time, trial) of a grid is one seeded trial
(:func:`rozyn_estimator.tools.trial.run_trial`). Trials run in chunks on local processes or on
a Dask distributed cluster (``--scheduler``); the parent process appends each finished
chunk to ``results.csv``, so an interrupted study resumes where it stopped. Each trial's
seed is a function of the study's seed base, the cell and the trial number only, and
each trial runs on one BLAS thread: the results are bit-identical whatever the number
of workers, and a finished study's ``results.csv`` is written in grid order.

Files in the output directory:

- ``study.json``: the settings (compared on ``--resume``) and a log of the runs;
- ``results.csv``: one row per trial (estimate, body modes, or the failure's reason);
- ``summary.csv`` / ``summary.md``: per cell mean, std, bias and failures;
- ``figures/*.png``: see :mod:`rozyn_estimator.tools.study.plots`.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import datetime
import functools
import json
import math
import os
import signal
import sys
import time
import zlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PARAM_NAMES, Estimate, PipelineConfig
from rozyn_estimator.tools.trial import (
    TrialResult,
    TrialSpec,
    default_jobs,
    limit_threads,
    run_trial,
    summarise,
)
from rozyn_estimator.vehicle import Vehicle, load_vehicle, vehicle_from_mapping

HELP = "Monte-Carlo grid of the thesis: speed x measurement time x road, tables and plots"
DESCRIPTION = (
    "Run seeded trials for every road, speed and measurement time of a grid (default: the "
    "thesis' chapter 5 grid, 2 roads x 8 speeds x 12 durations x 100 trials), on local "
    "processes or a Dask cluster. Writes results.csv (one row per trial, as they finish), "
    "summary.csv/.md (mean, std, bias, failures per cell), figures/*.png and study.json "
    "into --out. An interrupted study continues with --resume."
)

STUDY_ROADS = ("iso", "laplace")
MANIFEST = "study.json"
RESULTS = "results.csv"
SUMMARY_CSV = "summary.csv"
SUMMARY_MD = "summary.md"
FIGURES = "figures"
MANIFEST_VERSION = 1
MODE_COLUMNS = ("mode1_freq_hz", "mode1_damping", "mode2_freq_hz", "mode2_damping")
COLUMNS = (
    "road", "speed_kmh", "duration_s", "trial", "seed", "status", "stage", *PARAM_NAMES, *MODE_COLUMNS,
    "reason",
)
THESIS_CELL = (100.0, 100.0)  # km/h, s: the condition of the thesis' Figs 5-3 to 5-10
DEFAULT_CHUNK_TRIALS = 25


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True, order=True)
class Cell:
    """One condition of the grid."""

    road: str
    speed_kmh: float
    duration_s: float

    @property
    def label(self) -> str:
        return f"{self.road}, {self.speed_kmh:g} km/h, {self.duration_s:g} s"


@dataclass(frozen=True)
class StudySettings:
    """What a study computes; ``study.json`` records it and ``--resume`` compares it."""

    roads: tuple[str, ...] = STUDY_ROADS
    speeds_kmh: tuple[float, ...] = tuple(float(v) for v in range(30, 101, 10))
    durations_s: tuple[float, ...] = tuple(float(v) for v in range(10, 121, 10))
    trials: int = 100
    amplitudes: str = "fixed"
    road_class: str = "A"
    laplace_nu: float = 1.0
    rate_hz: float = 100.0
    noise_std_mps2: float = 0.0
    method: str = ""  # "" -> default_method()
    seed_base: int = 0
    vehicle: Vehicle = field(default_factory=Vehicle)

    def __post_init__(self) -> None:
        if not self.method:
            object.__setattr__(self, "method", default_method())
        for road in self.roads:
            if road not in STUDY_ROADS:
                raise ConfigError(f"roads: unknown road {road!r}; choose from {', '.join(STUDY_ROADS)}")
        for name in ("roads", "speeds_kmh", "durations_s"):
            values = getattr(self, name)
            if not values:
                raise ConfigError(f"{name}: the grid needs at least one value")
            if len(set(values)) != len(values):
                raise ConfigError(f"{name}: repeated values in {', '.join(map(_fmt, values))}")
        if self.trials < 1:
            raise ConfigError(f"trials: must be >= 1, got {self.trials}")
        if self.seed_base < 0:
            raise ConfigError(f"seed_base: must be >= 0, got {self.seed_base}")
        if self.method not in METHODS:
            raise ConfigError(f"method: must be one of {', '.join(METHODS)}, got {self.method!r}")
        for cell in (self.cells()[0], self.cells()[-1]):
            self.trial_spec(cell)  # validates road, speed, duration, rate, noise

    def cells(self) -> list[Cell]:
        """The grid in its canonical order: road, then speed, then duration."""
        return [Cell(r, s, d) for r in self.roads for s in self.speeds_kmh for d in self.durations_s]

    @property
    def n_trials(self) -> int:
        return len(self.roads) * len(self.speeds_kmh) * len(self.durations_s) * self.trials

    def pipeline_config(self) -> PipelineConfig:
        """The method's settings without the per-trial covariance (the study is the spread)."""
        cfg = METHODS[self.method]
        if self.method == default_method():
            cfg = _without_refinement(cfg)
        return cfg.replace(variance="none")

    def trial_spec(self, cell: Cell) -> TrialSpec:
        return TrialSpec(
            road=cell.road, road_class=self.road_class, amplitudes=self.amplitudes,
            laplace_nu=self.laplace_nu, speed_kmh=cell.speed_kmh, duration_s=cell.duration_s,
            rate_hz=self.rate_hz, noise_std_mps2=self.noise_std_mps2, vehicle=self.vehicle,
            method=self.method, pipeline=self.pipeline_config(),
        )

    def seed(self, cell: Cell, trial: int) -> int:
        """The road seed of a trial: a function of the seed base, the cell and the trial only.

        Adding cells to a grid, or running it on more workers, leaves every other trial
        as it was; ``rozyn trial --seed SEED`` with the cell's options repeats a trial.
        """
        key = [
            self.seed_base, zlib.crc32(cell.road.encode()), round(cell.speed_kmh * 1000),
            round(cell.duration_s * 1000), trial,
        ]
        return int(np.random.SeedSequence(key).generate_state(1, dtype=np.uint32)[0] >> 1)

    def to_dict(self) -> dict[str, Any]:
        """JSON form (``study.json``), including the pipeline settings the method stands for."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        out["roads"] = list(self.roads)
        out["speeds_kmh"] = list(self.speeds_kmh)
        out["durations_s"] = list(self.durations_s)
        out["vehicle"] = self.vehicle.to_dict()
        out["pipeline"] = dataclasses.asdict(self.pipeline_config())
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> StudySettings:
        values = {k: v for k, v in data.items() if k != "pipeline"}
        try:
            values["vehicle"] = vehicle_from_mapping(values.get("vehicle", {}), source=MANIFEST)
            for name in ("roads", "speeds_kmh", "durations_s"):
                values[name] = tuple(values[name])
            return cls(**values)
        except (KeyError, TypeError) as exc:
            raise ConfigError(f"{MANIFEST}: not a study manifest this version can read ({exc})") from None


def default_method() -> str:
    """The study's default method: Rozyn's pipeline (``rozyn``), the thesis' subject."""
    return "rozyn" if "rozyn" in METHODS else next(iter(METHODS))


def _without_refinement(cfg: PipelineConfig) -> PipelineConfig:
    """The Rozyn stage of a method: no refinement after Rozyn's pipeline, if it has one."""
    return cfg.replace(refine="none") if getattr(cfg, "refine", "none") != "none" else cfg


def _fmt(value: float) -> str:
    """A grid value as written in files: short, and exact for up to 12 significant digits."""
    return f"{value:.12g}"


def parse_grid(text: str, name: str) -> tuple[float, ...]:
    """``"30:100:10"`` (start:stop:step, stop included), ``"30,50,100"`` or a mix -> values.

    Raises:
        ConfigError: the text is not such a list of positive numbers.
    """
    values: list[float] = []
    usage = f"{name}: expected START:STOP:STEP, a comma list, or both (e.g. 30:100:10 or 30,60,100)"
    for part in text.split(","):
        bits = part.strip().split(":")
        try:
            numbers = [float(b) for b in bits]
        except ValueError:
            raise ConfigError(f"{usage}, got {text!r}") from None
        if len(numbers) == 1:
            values.append(numbers[0])
        elif len(numbers) == 3:
            values.extend(_range(*numbers, name=name))
        else:
            raise ConfigError(f"{usage}, got {text!r}")
    if not all(math.isfinite(v) and v > 0 for v in values):
        raise ConfigError(f"{name}: values must be positive numbers, got {text!r}")
    if len(set(values)) != len(values):
        raise ConfigError(f"{name}: repeated values in {text!r}")
    return tuple(sorted(values))


def _range(start: float, stop: float, step: float, name: str) -> list[float]:
    if not step > 0 or stop < start:
        raise ConfigError(f"{name}: START:STOP:STEP needs STEP > 0 and STOP >= START, got "
                          f"{_fmt(start)}:{_fmt(stop)}:{_fmt(step)}")
    count = math.floor((stop - start) / step + 1e-9) + 1
    return [round(start + k * step, 9) for k in range(count)]


def parse_roads(text: str) -> tuple[str, ...]:
    roads = tuple(r.strip().lower() for r in text.split(",") if r.strip())
    for road in roads:
        if road not in STUDY_ROADS:
            raise ConfigError(f"roads: unknown road {road!r}; choose from {', '.join(STUDY_ROADS)}")
    return roads


# --------------------------------------------------------------------------- trial rows


@dataclass(frozen=True)
class TrialRow:
    """One line of ``results.csv``."""

    cell: Cell
    trial: int
    seed: int
    status: str  # "ok", "failed" (no honest estimate) or "error" (the trial raised an exception)
    params: tuple[float, float, float] | None
    modes: tuple[float, float, float, float] | None  # f1 [Hz], zeta1, f2 [Hz], zeta2
    reason: str = ""
    stage: str = "rozyn"  # the estimator stage whose numbers these are

    @property
    def key(self) -> tuple[str, float, float, int]:
        return (self.cell.road, self.cell.speed_kmh, self.cell.duration_s, self.trial)

    @classmethod
    def from_result(cls, cell: Cell, trial: int, result: TrialResult) -> TrialRow:
        est = result.estimate
        modes = None
        if len(est.modes) >= 2:
            modes = tuple(float(v) for m in est.modes[:2] for v in (m.freq_hz, m.damping_ratio))
        params = None if est.params is None else tuple(float(v) for v in est.params)
        return cls(cell, trial, result.seed, est.status, params, modes, est.reason,
                   getattr(est, "stage", "rozyn"))

    def to_csv(self) -> list[str]:
        def num(values: Sequence[float] | None, n: int) -> list[str]:
            return [""] * n if values is None else [repr(float(v)) for v in values]

        c = self.cell
        return [c.road, _fmt(c.speed_kmh), _fmt(c.duration_s), str(self.trial), str(self.seed),
                self.status, self.stage, *num(self.params, 3), *num(self.modes, 4), self.reason]

    @classmethod
    def from_csv(cls, record: dict[str, str]) -> TrialRow:
        def nums(names: Sequence[str]) -> tuple[float, ...] | None:
            text = [record[n] for n in names]
            return None if any(t == "" for t in text) else tuple(float(t) for t in text)

        cell = Cell(record["road"], float(record["speed_kmh"]), float(record["duration_s"]))
        return cls(cell, int(record["trial"]), int(record["seed"]), record["status"],
                   nums(PARAM_NAMES), nums(MODE_COLUMNS), record["reason"], record["stage"])

    def to_trial_result(self, truth: np.ndarray) -> TrialResult:
        params = None if self.params is None else np.array(self.params)
        est = Estimate(status=self.status, reason=self.reason, params=params)
        return TrialResult(seed=self.seed, estimate=est, truth=truth, sim_ms=float("nan"))


def read_results(path: Path) -> list[TrialRow]:
    """The complete rows of a results file (a line cut short by an interruption is skipped)."""
    rows, _ = _read_results(path)
    return rows


def _read_results(path: Path) -> tuple[list[TrialRow], bool]:
    """(rows, clean): ``clean`` is False when the file ends in a partial line."""
    with path.open(newline="") as f:
        text = f.read()
    clean = text == "" or text.endswith("\n")
    lines = text.splitlines(keepends=True)
    if not clean:
        lines = lines[:-1]
    reader = csv.DictReader(lines)
    if tuple(reader.fieldnames or ()) != COLUMNS:
        raise ConfigError(f"{path}: not a study results file (header {reader.fieldnames})")
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


# --------------------------------------------------------------------------- work


@dataclass(frozen=True)
class Chunk:
    """Trials of one cell, run as one task (amortises process and scheduler overhead)."""

    spec: TrialSpec
    cell: Cell
    trials: tuple[int, ...]
    seeds: tuple[int, ...]


@functools.cache
def _one_blas_thread() -> None:
    """limit_threads() once per process (Dask workers have no initialiser of ours)."""
    limit_threads()


def run_chunk(chunk: Chunk) -> list[TrialRow]:
    """Run a chunk's trials (in a worker process, a Dask worker or here)."""
    _one_blas_thread()
    return [_run_one(chunk, trial, seed) for trial, seed in zip(chunk.trials, chunk.seeds, strict=True)]


def _run_one(chunk: Chunk, trial: int, seed: int) -> TrialRow:
    """One trial; an exception becomes an ``error`` row so one bad road cannot stop a study."""
    try:
        return TrialRow.from_result(chunk.cell, trial, run_trial(chunk.spec, seed))
    except Exception as exc:
        return TrialRow(chunk.cell, trial, seed, "error", None, None, f"{type(exc).__name__}: {exc}", "")


def plan_chunks(
    settings: StudySettings, done: set[tuple[str, float, float, int]], chunk_trials: int
) -> list[Chunk]:
    """The missing trials, in chunks of one cell, longest measurement time first.

    Longest first keeps the end of a parallel run short (the last tasks are the cheap
    ones); the order does not affect any result.
    """
    chunks = []
    for cell in settings.cells():
        todo = [t for t in range(settings.trials)
                if (cell.road, cell.speed_kmh, cell.duration_s, t) not in done]
        if not todo:
            continue
        spec = settings.trial_spec(cell)
        for i in range(0, len(todo), chunk_trials):
            trials = tuple(todo[i : i + chunk_trials])
            chunks.append(Chunk(spec, cell, trials, tuple(settings.seed(cell, t) for t in trials)))
    chunks.sort(key=lambda c: -c.cell.duration_s)
    return chunks


def _ignore_sigint() -> None:
    """Worker initialiser: the parent handles Ctrl-C and stops the pool cleanly."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    limit_threads()


def local_results(chunks: Sequence[Chunk], jobs: int) -> Iterator[list[TrialRow]]:
    """Chunk results as they finish, on ``jobs`` local processes (1: in this process)."""
    if jobs == 1 or len(chunks) <= 1:
        for chunk in chunks:
            yield run_chunk(chunk)
        return
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=_ignore_sigint)
    try:
        futures = [pool.submit(run_chunk, c) for c in chunks]
        for future in as_completed(futures):
            yield future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def connect_scheduler(address: str) -> Any:
    """A ``distributed.Client`` of the Dask cluster at ``address`` (dask is imported only here).

    Raises:
        ConfigError: dask is not installed or the scheduler does not answer within 10 s.
    """
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError("--scheduler needs dask[distributed]: pip install 'dask[distributed]'") from None
    try:
        return Client(address, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ConfigError(f"--scheduler: cannot connect to {address}: {exc}") from None


def dask_results(chunks: Sequence[Chunk], client: Any) -> Iterator[list[TrialRow]]:
    """Chunk results as they finish, on a Dask distributed cluster.

    The workers need this package installed (the same version as here).
    """
    from distributed import as_completed as dask_completed

    futures = client.map(run_chunk, chunks, pure=False)
    try:
        for _, rows in dask_completed(futures, loop=client.loop, with_results=True):
            yield rows
    finally:
        client.cancel(futures)


# --------------------------------------------------------------------------- summary


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


def _robust_std(params: Sequence[tuple[float, float, float] | None]) -> np.ndarray:
    if len(params) < 2:
        return np.full(3, np.nan)
    q1, q3 = np.percentile(np.array(params, dtype=float), [25, 75], axis=0)
    return (q3 - q1) / 1.349


SUMMARY_STATS = ("mean", "std", "bias_pct", "within_6pct", "robust_std")
SUMMARY_COLUMNS = (
    "road", "speed_kmh", "duration_s", "trials", "failures",
    *(f"{p}_{stat}" for p in PARAM_NAMES for stat in SUMMARY_STATS),
)


def write_summary(summaries: Sequence[CellSummary], csv_path: Path, md_path: Path, title: str) -> None:
    """The per-cell table as CSV (full precision) and Markdown (rounded, for reading)."""
    with csv_path.open("w", newline="") as f:
        out = csv.writer(f, lineterminator="\n")
        out.writerow(SUMMARY_COLUMNS)
        for s in summaries:
            stats = [getattr(s, stat)[i] for i in range(3) for stat in SUMMARY_STATS]
            out.writerow([s.cell.road, _fmt(s.cell.speed_kmh), _fmt(s.cell.duration_s), s.n, s.failures,
                          *(repr(float(v)) for v in stats)])
    md_path.write_text(summary_markdown(summaries, title))


def summary_markdown(summaries: Sequence[CellSummary], title: str) -> str:
    head = ("| road | speed [km/h] | time [s] | trials | failures | mean m [kg] | std m [kg] | bias m [%] "
            "| mean I_yy [kg m²] | std I_yy [kg m²] | bias I_yy [%] | mean l_f [m] | std l_f [m] "
            "| bias l_f [%] |")
    lines = [f"# {title}", "", head, "|" + "---|" * (head.count("|") - 1)]
    for s in summaries:
        cells = [s.cell.road, _fmt(s.cell.speed_kmh), _fmt(s.cell.duration_s), str(s.n), str(s.failures)]
        for i, (mean_fmt, std_fmt) in enumerate((("{:.1f}", "{:.2f}"), ("{:.1f}", "{:.2f}"),
                                                   ("{:.4f}", "{:.4f}"))):
            cells += [_num(mean_fmt, s.mean[i]), _num(std_fmt, s.std[i]), _num("{:+.2f}", s.bias_pct[i])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _num(fmt: str, value: float) -> str:
    return "–" if not np.isfinite(value) else fmt.format(value)


# --------------------------------------------------------------------------- correlations


@dataclass(frozen=True)
class CellCorrelations:
    """Normalised autocorrelations of a cell's trials (the thesis' Figs 5-3, 5-4, 5-14, 5-15)."""

    cell: Cell
    lag_s: np.ndarray  # (n_lags,)
    acf: np.ndarray  # (n_trials, n_lags, 2): R_ii(tau) / R_ii(0), front and rear
    fit_lags_s: tuple[float, float]  # the lags the pipeline identifies from [s]


def cell_correlations(
    settings: StudySettings, cell: Cell, trials: Sequence[int] | None = None, max_lag_s: float = 3.0
) -> CellCorrelations:
    """Recompute a cell's autocorrelations from the simulation (they are not stored per trial).

    The same seeds give the same records as the study's trials (default: its first 100).
    """
    from rozyn_estimator.method.correlation import correlation_sums
    from sim_node.simulation import Simulation

    _one_blas_thread()
    trials = range(min(100, settings.trials)) if trials is None else trials
    spec = settings.trial_spec(cell)
    max_lag = round(max_lag_s * settings.rate_hz)
    acf = np.empty((len(trials), max_lag + 1, 2))
    for i, trial in enumerate(trials):
        y = Simulation(spec.sim_config(settings.seed(cell, trial))).run(cell.duration_s).accel_mps2
        sums = correlation_sums(y - y.mean(axis=0), max_lag)[0]
        acf[i] = np.column_stack([sums[:, 0, 0] / sums[0, 0, 0], sums[:, 1, 1] / sums[0, 1, 1]])
    return CellCorrelations(cell, np.arange(max_lag + 1) / settings.rate_hz, acf,
                            fit_lag_window_s(settings.pipeline_config(), settings.vehicle, cell.speed_kmh))


def focus_correlations(
    settings: StudySettings, cells: Sequence[Cell], pmap: Callable[..., Iterable[Any]] = map, parts: int = 1
) -> list[CellCorrelations]:
    """:func:`cell_correlations` of several cells, each cut into ``parts`` tasks for ``pmap``."""
    trials = np.array_split(np.arange(min(100, settings.trials)), parts)
    tasks = [(settings, cell, tuple(int(t) for t in part)) for cell in cells for part in trials if len(part)]
    pieces = list(pmap(_correlation_task, tasks))
    out = []
    for cell in cells:
        mine = [p for p in pieces if p.cell == cell]
        out.append(dataclasses.replace(mine[0], acf=np.concatenate([p.acf for p in mine])))
    return out


def _correlation_task(task: tuple[StudySettings, Cell, tuple[int, ...]]) -> CellCorrelations:
    return cell_correlations(*task)


def fit_lag_window_s(cfg: PipelineConfig, vehicle: Vehicle, speed_kmh: float) -> tuple[float, float]:
    """First and last correlation lag the pipeline uses at a speed [s] (pipeline step 1)."""
    first = cfg.min_lag_s
    if cfg.skip_wheelbase_delay:
        first = max(first, vehicle.wheelbase_m / (speed_kmh / 3.6))
    return first, first + cfg.max_lag_s


# --------------------------------------------------------------------------- running


@dataclass(frozen=True)
class RunOptions:
    """How to run a study (none of this changes a result)."""

    jobs: int = 1
    scheduler: str | None = None  # Dask scheduler address; None: local processes
    chunk_trials: int = DEFAULT_CHUNK_TRIALS
    progress: bool = False


@dataclass(frozen=True)
class RunReport:
    """What one invocation computed."""

    trials_run: int
    trials_total: int
    wall_s: float

    @property
    def trials_per_s(self) -> float:
        return self.trials_run / self.wall_s if self.wall_s > 0 else float("nan")


def prepare_dir(out_dir: Path, settings: StudySettings, resume: bool, force: bool) -> list[TrialRow]:
    """Make ``out_dir`` ready for ``settings``; return the trials already done there.

    Raises:
        ConfigError: the directory holds another study, or a study and neither ``resume``
            nor ``force`` was asked for.
    """
    if resume and force:
        raise ConfigError("--resume and --force exclude each other")
    manifest = out_dir / MANIFEST
    results = out_dir / RESULTS
    exists = manifest.exists() or results.exists()
    if exists and force:
        remove_outputs(out_dir)
    elif exists and not resume:
        raise ConfigError(f"{out_dir} already holds a study; continue it with --resume, start it over "
                          f"with --force, or choose another --out")
    elif exists:
        if not manifest.exists():
            raise ConfigError(f"{out_dir}: {RESULTS} without {MANIFEST}: cannot check its settings; "
                              f"use --force to start over")
        check_same_study(load_manifest(out_dir), settings, out_dir)
        if results.exists():
            rows, clean = _read_results(results)
            wanted = set(settings.cells())
            kept = [r for r in rows if r.cell in wanted and r.trial < settings.trials]
            if not clean or len(kept) != len(rows):
                write_results(results, kept)
            return kept
    out_dir.mkdir(parents=True, exist_ok=True)
    return []


def remove_outputs(out_dir: Path) -> None:
    """Delete the files a study writes (and nothing else) from ``out_dir``."""
    for name in (MANIFEST, RESULTS, SUMMARY_CSV, SUMMARY_MD, RESULTS + ".tmp"):
        (out_dir / name).unlink(missing_ok=True)
    figures = out_dir / FIGURES
    if figures.is_dir():
        for png in figures.glob("*.png"):
            png.unlink()


def load_manifest(out_dir: Path) -> dict[str, Any]:
    path = out_dir / MANIFEST
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{out_dir}: no {MANIFEST}: not a study directory") from None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None
    if not isinstance(data, dict) or data.get("version") != MANIFEST_VERSION or "settings" not in data:
        raise ConfigError(f"{path}: not a study manifest of version {MANIFEST_VERSION}")
    return data


def write_manifest(out_dir: Path, data: dict[str, Any]) -> None:
    tmp = out_dir / (MANIFEST + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, out_dir / MANIFEST)


def check_same_study(manifest: dict[str, Any], settings: StudySettings, out_dir: Path) -> None:
    """Refuse to resume a study with other settings (naming what differs)."""
    old = manifest["settings"]
    new = json.loads(json.dumps(settings.to_dict()))
    differ = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    if differ:
        details = "; ".join(f"{k}: {_short(old.get(k))} there, {_short(new.get(k))} asked" for k in differ)
        raise ConfigError(f"{out_dir} holds a different study ({details}); use another --out, "
                          f"or --force to start over")


def _short(value: Any) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def run_study(
    settings: StudySettings, out_dir: Path, options: RunOptions, done: Sequence[TrialRow] = (),
    client: Any = None,
) -> tuple[list[TrialRow], RunReport]:
    """Run the trials of ``settings`` missing from ``done``, appending them to results.csv.

    Args:
        settings: the study.
        out_dir: a directory made ready by :func:`prepare_dir`.
        options: workers, chunking, progress bar.
        done: trials already in results.csv.
        client: a connected ``distributed.Client`` when ``options.scheduler`` is set
            (connected here, and closed again, when not given).

    Returns:
        All rows (in grid order) and what this call computed. On an interruption
        (Ctrl-C) the finished trials stay in results.csv, the manifest says so, and the
        KeyboardInterrupt goes on to the caller.
    """
    if options.scheduler and client is None:
        client = connect_scheduler(options.scheduler)
        try:
            return run_study(settings, out_dir, options, done, client)
        finally:
            client.close()
    manifest = _manifest_with_run(out_dir, settings, options)
    rows = list(done)
    chunks = plan_chunks(settings, {r.key for r in rows}, options.chunk_trials)
    todo = sum(len(c.trials) for c in chunks)
    writer = ResultsWriter(out_dir / RESULTS)
    bar = _progress(settings.n_trials, len(rows), options.progress)
    started = time.perf_counter()
    status = "interrupted"
    try:
        source = dask_results(chunks, client) if client else local_results(chunks, options.jobs)
        for chunk_rows in source:
            writer.write(chunk_rows)
            rows.extend(chunk_rows)
            bar.update(len(chunk_rows))
        status = "complete"
    finally:
        wall_s = time.perf_counter() - started
        bar.close()
        writer.close()
        report = RunReport(len(rows) - len(done), settings.n_trials, wall_s)
        _finish_run(out_dir, manifest, status, report)
        if status != "complete":
            print(f"rozyn study: stopped after {len(rows)} of {settings.n_trials} trials; "
                  f"continue with --resume --out {out_dir}", file=sys.stderr)
    rows = sort_rows(settings, rows)
    if todo:
        write_results(out_dir / RESULTS, rows)
    return rows, report


def _manifest_with_run(out_dir: Path, settings: StudySettings, options: RunOptions) -> dict[str, Any]:
    path = out_dir / MANIFEST
    manifest = load_manifest(out_dir) if path.exists() else {
        "version": MANIFEST_VERSION, "tool": "rozyn study", "settings": settings.to_dict(), "runs": [],
    }
    manifest["runs"].append({
        "started": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "status": "running",
        "workers": options.scheduler or f"{options.jobs} local process(es)",
        "cpus": os.cpu_count(),
        "chunk_trials": options.chunk_trials,
    })
    write_manifest(out_dir, manifest)
    return manifest


def _finish_run(out_dir: Path, manifest: dict[str, Any], status: str, report: RunReport) -> None:
    manifest["runs"][-1].update({
        "status": status,
        "trials_run": report.trials_run,
        "wall_s": round(report.wall_s, 3),
        "trials_per_s": round(report.trials_per_s, 2) if report.trials_run else None,
    })
    write_manifest(out_dir, manifest)


def _progress(total: int, initial: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="trial", disable=not enabled, file=sys.stderr,
                dynamic_ncols=True, smoothing=0.05, desc="study", leave=False)


# --------------------------------------------------------------------------- outputs


def nearest_cell(settings: StudySettings, speed_kmh: float, duration_s: float) -> tuple[float, float]:
    """The grid's (speed, duration) closest to the one asked for (relative distance)."""
    speed = min(settings.speeds_kmh, key=lambda v: abs(v / speed_kmh - 1))
    duration = min(settings.durations_s, key=lambda v: abs(v / duration_s - 1))
    return speed, duration


def write_outputs(
    out_dir: Path, settings: StudySettings, rows: Sequence[TrialRow],
    focus: tuple[float, float] | None = None, jobs: int = 1,
) -> list[Path]:
    """Summary tables and figures from the results, on ``jobs`` processes; returns the files written."""
    from rozyn_estimator.tools.study import plots as study_plots

    summaries = summarise_cells(settings, rows)
    write_summary(summaries, out_dir / SUMMARY_CSV, out_dir / SUMMARY_MD, title=study_title(settings))
    speed, duration = nearest_cell(settings, *(focus or THESIS_CELL))
    focus_cells = [Cell(road, speed, duration) for road in settings.roads]
    if jobs == 1:
        correlations = focus_correlations(settings, focus_cells)
        figures = study_plots.plot_study(out_dir / FIGURES, settings, summaries, rows, correlations)
    else:
        with ProcessPoolExecutor(max_workers=jobs, initializer=_ignore_sigint) as pool:
            correlations = focus_correlations(settings, focus_cells, pool.map, parts=jobs)
            figures = study_plots.plot_study(out_dir / FIGURES, settings, summaries, rows, correlations,
                                             pool.map)
    return [out_dir / SUMMARY_CSV, out_dir / SUMMARY_MD, *figures]


def study_title(settings: StudySettings) -> str:
    noise = f", sensor noise {settings.noise_std_mps2:g} m/s²" if settings.noise_std_mps2 else ""
    return (f"Study: ISO 8608 class {settings.road_class} base road, {settings.amplitudes} amplitudes"
            f"{noise}, method {settings.method}, {settings.trials} trials per cell")


# --------------------------------------------------------------------------- command line


def add_arguments(p: argparse.ArgumentParser) -> None:
    grid = p.add_argument_group("grid (default: the thesis' chapter 5 grid)")
    grid.add_argument("--roads", metavar="LIST", help="comma list of iso, laplace (default: iso,laplace)")
    grid.add_argument("--speeds-kmh", metavar="GRID",
                      help="speeds: START:STOP:STEP and/or a comma list (default: 30:100:10)")
    grid.add_argument("--durations-s", metavar="GRID",
                      help="measurement times: START:STOP:STEP and/or a comma list (default: 10:120:10)")
    grid.add_argument("--trials", type=int, metavar="N", help="random roads per cell (default: 100)")
    grid.add_argument("--amplitudes", choices=("fixed", "gaussian"),
                      help="fixed: the thesis' road generator; gaussian: a true Gaussian road "
                           "(default: fixed)")
    grid.add_argument("--road-class", metavar="A..H", help="ISO 8608 class of the base road (default: A)")
    grid.add_argument("--laplace-nu", type=float, metavar="NU", help="Laplace road variance nu (default: 1)")
    grid.add_argument("--rate-hz", type=float, metavar="HZ", help="accelerometer rate (default: 100)")
    grid.add_argument("--noise-std-mps2", type=float, metavar="MPS2", help="white sensor noise (default: 0)")
    grid.add_argument("--method", choices=tuple(METHODS), metavar="NAME",
                      help=f"estimation method: {', '.join(METHODS)} (default: {default_method()}, "
                           "Rozyn's pipeline without refinement)")
    grid.add_argument("--vehicle", metavar="FILE.yaml", help="vehicle parameters (default: thesis Table 5-1)")
    grid.add_argument("--seed-base", type=int, metavar="N", help="changes every road seed (default: 0)")

    run = p.add_argument_group("running")
    run.add_argument("--out", required=True, type=Path, metavar="DIR", help="output directory")
    mode = run.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true",
                      help="continue the study in --out (grid options may be left out; given ones "
                           "must match)")
    mode.add_argument("--force", action="store_true", help="replace the study in --out")
    mode.add_argument("--plots-only", action="store_true",
                      help="only rebuild the tables and figures from --out's results")
    workers = run.add_mutually_exclusive_group()
    workers.add_argument("--jobs", type=int, metavar="N", help="local worker processes (default: all cores)")
    workers.add_argument("--scheduler", metavar="ADDRESS",
                         help="run on the Dask distributed cluster at ADDRESS (e.g. tcp://host:8786)")
    run.add_argument("--chunk-trials", type=int, default=DEFAULT_CHUNK_TRIALS, metavar="N",
                     help=f"trials per task (default: {DEFAULT_CHUNK_TRIALS})")
    run.add_argument("--cell", metavar="KMH,S",
                     help="speed and time of the histograms, boxplot and correlation figures "
                          "(default: the grid's nearest to 100,100, the thesis' condition)")
    run.add_argument("--no-plots", action="store_true", help="write the tables but no figures")
    run.add_argument("--quiet", action="store_true", help="no progress bar")


_SETTING_ARGS = ("roads", "speeds_kmh", "durations_s", "trials", "amplitudes", "road_class", "laplace_nu",
                 "rate_hz", "noise_std_mps2", "method", "seed_base", "vehicle")


def settings_from_args(args: argparse.Namespace, base: StudySettings | None = None) -> StudySettings:
    """The study's settings: ``base`` (or the defaults) with the options given on the command line."""
    parsers: dict[str, Callable[[Any], Any]] = {
        "roads": parse_roads,
        "speeds_kmh": lambda t: parse_grid(t, "speeds-kmh"),
        "durations_s": lambda t: parse_grid(t, "durations-s"),
        "road_class": lambda t: str(t).upper(),
        "vehicle": load_vehicle,
    }
    changes = {}
    for name in _SETTING_ARGS:
        value = getattr(args, name, None)
        if value is not None:
            changes[name] = parsers.get(name, lambda v: v)(value)
    try:
        return dataclasses.replace(base, **changes) if base else StudySettings(**changes)
    except ConfigError:
        raise
    except (TypeError, ValueError) as exc:
        raise ConfigError(str(exc)) from None


def _parse_cell(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        speed, duration = (float(v) for v in text.split(","))
    except ValueError:
        raise ConfigError(f"--cell: expected KMH,S (e.g. 100,100), got {text!r}") from None
    if not (speed > 0 and duration > 0):
        raise ConfigError(f"--cell: speed and time must be positive, got {text!r}")
    return speed, duration


def run(args: argparse.Namespace) -> int:
    """``rozyn study``."""
    out_dir: Path = args.out
    focus = _parse_cell(args.cell)
    if args.chunk_trials < 1:
        raise ConfigError(f"--chunk-trials: must be >= 1, got {args.chunk_trials}")
    if args.jobs is not None and args.jobs < 1:
        raise ConfigError(f"--jobs: must be >= 1, got {args.jobs}")
    settings, rows = _stored_study(args) if args.plots_only else _run_grid(args)
    if len(rows) < settings.n_trials:
        print(f"rozyn study: {out_dir} holds {len(rows)} of {settings.n_trials} trials; "
              f"tables and figures cover those", file=sys.stderr)
    started = time.perf_counter()
    if args.no_plots:
        summaries = summarise_cells(settings, rows)
        write_summary(summaries, out_dir / SUMMARY_CSV, out_dir / SUMMARY_MD, study_title(settings))
    else:
        if not args.quiet:
            print("rozyn study: writing tables and figures", file=sys.stderr)
        write_outputs(out_dir, settings, rows, focus, 1 if args.scheduler else (args.jobs or default_jobs()))
    if not args.plots_only:
        manifest = load_manifest(out_dir)
        manifest["runs"][-1]["outputs_s"] = round(time.perf_counter() - started, 3)
        write_manifest(out_dir, manifest)
    _print_done(out_dir, settings, rows, figures=not args.no_plots)
    return 0


def _stored_study(args: argparse.Namespace) -> tuple[StudySettings, list[TrialRow]]:
    """``--plots-only``: the settings and results in --out (options given must match them)."""
    manifest = load_manifest(args.out)
    settings = StudySettings.from_dict(manifest["settings"])
    if any(getattr(args, n, None) is not None for n in _SETTING_ARGS):
        check_same_study(manifest, settings_from_args(args, settings), args.out)
    if not (args.out / RESULTS).exists():
        raise ConfigError(f"{args.out}: no {RESULTS} to plot")
    return settings, read_results(args.out / RESULTS)


def _run_grid(args: argparse.Namespace) -> tuple[StudySettings, list[TrialRow]]:
    """A new, replaced (--force) or resumed (--resume) study in --out."""
    base = None
    if args.resume and (args.out / MANIFEST).exists():
        base = StudySettings.from_dict(load_manifest(args.out)["settings"])
    settings = settings_from_args(args, base)
    options = RunOptions(
        jobs=args.jobs or default_jobs(), scheduler=args.scheduler, chunk_trials=args.chunk_trials,
        progress=not args.quiet and sys.stderr.isatty(),
    )
    client = connect_scheduler(args.scheduler) if args.scheduler else None  # before touching --out
    try:
        done = prepare_dir(args.out, settings, resume=args.resume, force=args.force)
        rows, report = run_study(settings, args.out, options, done, client)
    finally:
        if client is not None:
            client.close()
    _print_run(report)
    return settings, rows


def _print_done(out_dir: Path, settings: StudySettings, rows: Sequence[TrialRow], figures: bool) -> None:
    failures = sum(r.status != "ok" for r in rows)
    print(f"{out_dir}: {len(rows)} trials ({failures} failed) in {len(settings.cells())} cells; "
          f"{SUMMARY_MD}, {SUMMARY_CSV}, {RESULTS}" + (f", {FIGURES}/" if figures else ""))
    errors = [r for r in rows if r.status == "error"]
    if errors:
        print(f"rozyn study: {len(errors)} trials raised an exception (status 'error' in {RESULTS}), "
              f"e.g. seed {errors[0].seed} ({errors[0].cell.label}): {errors[0].reason}", file=sys.stderr)


def _print_run(report: RunReport) -> None:
    if report.trials_run:
        print(f"ran {report.trials_run} trials in {report.wall_s:.1f} s ({report.trials_per_s:.0f} trials/s)")
    else:
        print("nothing to run: every trial is in the results already")


def bench_trials_per_second(repeats: int = 1) -> float:
    """Trials per second on one core over a spread of the thesis grid (``rozyn bench``).

    One trial per (road, duration) at 60 km/h, durations 10 to 120 s: the mix of a full
    study. Multiply by the cores for a study's rate.
    """
    settings = StudySettings(speeds_kmh=(60.0,), trials=1)
    chunks = plan_chunks(settings, set(), 1)
    run_chunk(chunks[0])  # warm-up
    started = time.perf_counter()
    for _ in range(repeats):
        for chunk in chunks:
            run_chunk(chunk)
    return repeats * len(chunks) / (time.perf_counter() - started)
