"""Running a study's trials: chunks of one cell, on local processes or a Dask cluster.

Every (road, speed, measurement time, trial) is one seeded trial
(:func:`rozyn_estimator.tools.trial.run.run_trial`, either car), or, with nested drives, every (road,
speed, trial) one seeded drive estimated after each measurement time
(:mod:`rozyn_estimator.tools.trial.drives`). :func:`run_study` runs the missing ones in chunks
(:class:`Chunk`) and appends each finished chunk to ``results.csv``. Each trial's seed
depends on the settings, the cell and the trial number only, and each trial runs on one
BLAS thread: the results are bit-identical whatever the number of workers.
"""

from __future__ import annotations

import datetime
import functools
import os
import signal
import sys
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tools.study.directory import load_manifest, new_manifest, write_manifest
from rozyn_estimator.tools.study.results import ResultsWriter, TrialRow, sort_rows, write_results
from rozyn_estimator.tools.study.settings import MANIFEST, RESULTS, Cell, StudySettings
from rozyn_estimator.tools.trial.drives import run_drive_args
from rozyn_estimator.tools.trial.run import limit_threads, run_trial
from rozyn_estimator.tools.trial.spec import TrialSpec

DEFAULT_CHUNK_TRIALS = 25


@dataclass(frozen=True)
class Chunk:
    """Trials of one cell, run as one task (amortises process and scheduler overhead); nested
    drives: of one road and speed, ``cell`` at the longest of ``durations_s``."""

    spec: TrialSpec
    cell: Cell
    trials: tuple[int, ...]
    seeds: tuple[int, ...]
    durations_s: tuple[float, ...] = ()  # nested drives: the measurement times of each; () independent

    @property
    def n_rows(self) -> int:
        """The results.csv rows it gives."""
        return len(self.trials) * max(1, len(self.durations_s))


@functools.cache
def one_blas_thread() -> None:
    """limit_threads() once per process (Dask workers have no initialiser of ours)."""
    limit_threads()


def run_chunk(chunk: Chunk) -> list[TrialRow]:
    """Run a chunk's trials (in a worker process, a Dask worker or here)."""
    one_blas_thread()
    run = _run_drive if chunk.durations_s else _run_one
    pairs = zip(chunk.trials, chunk.seeds, strict=True)
    return [row for trial, seed in pairs for row in run(chunk, trial, seed)]


def _run_one(chunk: Chunk, trial: int, seed: int) -> list[TrialRow]:
    """One trial; an exception becomes an ``error`` row so one bad road cannot stop a study."""
    try:
        spec = chunk.spec
        result = run_trial(spec, seed)
        return [TrialRow.from_result(chunk.cell, trial, result)]
    except Exception as exc:
        return [_error_row(chunk.cell, trial, seed, exc)]


def _run_drive(chunk: Chunk, trial: int, seed: int) -> list[TrialRow]:
    """One nested drive: a row per measurement time (all ``error`` rows if it raises)."""
    cells = [Cell(chunk.cell.road, chunk.cell.speed_kmh, d) for d in sorted(chunk.durations_s)]
    try:
        results = run_drive_args((chunk.spec, seed, chunk.durations_s))
        return [TrialRow.from_result(cell, trial, r) for cell, r in zip(cells, results, strict=True)]
    except Exception as exc:
        return [_error_row(cell, trial, seed, exc) for cell in cells]


def _error_row(cell: Cell, trial: int, seed: int, exc: Exception) -> TrialRow:
    return TrialRow(cell, trial, seed, "error", None, None, f"{type(exc).__name__}: {exc}", "")


def plan_chunks(
    settings: StudySettings, done: set[tuple[str, float, float, int]], chunk_trials: int
) -> list[Chunk]:
    """The missing trials, in chunks of one cell, longest measurement time first (nested
    drives: the drives with a missing measurement time, in chunks of one road and speed).

    Longest first keeps the end of a parallel run short (the last tasks are the cheap
    ones); the order does not affect any result.
    """
    if settings.nested:
        return _drive_chunks(settings, done, chunk_trials)
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


def _drive_chunks(
    settings: StudySettings, done: set[tuple[str, float, float, int]], chunk_trials: int
) -> list[Chunk]:
    """The nested drives with a measurement time missing from ``done`` (rerun whole: each
    time's estimate starts from the one before; run_study keeps the missing rows)."""
    chunks = []
    for road in settings.roads:
        for speed in settings.speeds_kmh:
            cell = settings.drive_cell(road, speed)
            todo = [t for t in range(settings.trials)
                    if any((road, speed, d, t) not in done for d in settings.durations_s)]
            spec = settings.trial_spec(cell)
            for i in range(0, len(todo), chunk_trials):
                trials = tuple(todo[i: i + chunk_trials])
                chunks.append(Chunk(spec, cell, trials, tuple(settings.seed(cell, t) for t in trials),
                                    settings.durations_s))
    return chunks


def ignore_sigint() -> None:
    """Worker initialiser: the parent handles Ctrl-C and stops the pool cleanly."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    limit_threads()


def local_results(chunks: Sequence[Chunk], jobs: int) -> Iterator[list[TrialRow]]:
    """Chunk results as they finish, on ``jobs`` local processes (1: in this process)."""
    if jobs == 1 or len(chunks) <= 1:
        for chunk in chunks:
            yield run_chunk(chunk)
        return
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=ignore_sigint)
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


def run_study(
    settings: StudySettings, out_dir: Path, options: RunOptions, done: Sequence[TrialRow] = (),
    client: Any = None,
) -> tuple[list[TrialRow], RunReport]:
    """Run the trials of ``settings`` missing from ``done``, appending them to results.csv.

    Args:
        settings: the study.
        out_dir: a directory made ready by
            :func:`~rozyn_estimator.tools.study.directory.prepare_dir`.
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
    done_keys = {r.key for r in rows}
    chunks = plan_chunks(settings, done_keys, options.chunk_trials)
    todo = sum(c.n_rows for c in chunks)
    writer = ResultsWriter(out_dir / RESULTS, model=settings.car)
    bar = _progress(settings.n_trials, len(rows), options.progress)
    started = time.perf_counter()
    status = "interrupted"
    try:
        source = dask_results(chunks, client) if client else local_results(chunks, options.jobs)
        for chunk_rows in source:
            chunk_rows = [r for r in chunk_rows if r.key not in done_keys]  # a resumed drive's done times
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
        write_results(out_dir / RESULTS, rows, settings.car)
    return rows, report


def _manifest_with_run(out_dir: Path, settings: StudySettings, options: RunOptions) -> dict[str, Any]:
    path = out_dir / MANIFEST
    manifest = load_manifest(out_dir) if path.exists() else new_manifest(settings)
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


def bench_trials_per_second(repeats: int = 1, method: str = "", amplitudes: str = "fixed",
                            noise_fraction: float = 0.0) -> float:
    """Trials per second on one core over a spread of the thesis grid (``rozyn bench``).

    One trial per (road, duration) at 60 km/h, durations 10 to 120 s: the mix of a full
    study, with ``method`` (default: the study's, Rozyn's pipeline; ``likelihood``: the
    refined estimator, as its study runs it: one nested drive per road), on roads of
    ``amplitudes`` with relative sensor noise ``noise_fraction``. Multiply by the cores for
    a study's rate.
    """
    settings = StudySettings(speeds_kmh=(60.0,), trials=1, method=method, amplitudes=amplitudes,
                             noise_fraction=noise_fraction)
    chunks = plan_chunks(settings, set(), 1)
    run_chunk(chunks[0])  # warm-up
    started = time.perf_counter()
    for _ in range(repeats):
        for chunk in chunks:
            run_chunk(chunk)
    return repeats * sum(c.n_rows for c in chunks) / (time.perf_counter() - started)
