"""``rozyn replay`` of a fleet: several bags, or directories of bags, in parallel.

Each bag is replayed exactly as ``rozyn replay BAG`` does it
(:func:`~rozyn_estimator.tools.replay.feed.replay_bag`) into ``<out>/<bag name>/``
(``updates.csv``, ``estimates/``, ``estimates.png``), on all local cores
(:func:`~rozyn_estimator.tools.trial.parallel_map`) or on the workers of a Dask cluster
(``--scheduler``, as ``rozyn study``: :func:`~rozyn_estimator.tools.study.work.connect_scheduler`).
One progress bar counts the bags; then one table (per bag: duration, last estimate ± std,
status, warnings) and ``<out>/fleet.csv`` with the same and more. A full-car bag shows its
roll inertia and lateral CoG too: the table and ``fleet.csv`` gain their columns when the
fleet holds one (a half-car fleet's are as they were; a half-car row leaves them empty).

A bag that cannot be replayed (damaged, truncated, foreign, no accelerometer topic, no
update due) is a ``failed`` row saying why; it never stops the others. The exit status
is 1 if any bag failed.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from rozyn_estimator.bag.reader import BAG_SUFFIXES
from rozyn_estimator.errors import BagError
from rozyn_estimator.online import LEVEL_NAMES, OK
from rozyn_estimator.tools.replay.feed import ReplayOptions, check_options, replay_bag
from rozyn_estimator.tools.replay.outputs import ReplayResult, published_estimate, utc

FLEET_CSV = "fleet.csv"
STATUSES = ("ok", "no estimate", "failed")  # an estimate published / none published / not replayed
PARAMS = ("mass_kg", "pitch_inertia_kgm2", "cog_from_front_axle_m")
FULL_PARAMS = (*PARAMS, "roll_inertia_kgm2", "cog_lateral_m")  # a full car's, the half car's first


@dataclass(frozen=True)
class FleetTask:
    """One bag to replay into ``out_dir`` (picklable: it travels to worker processes)."""

    bag: Path
    out_dir: Path
    options: ReplayOptions


@dataclass(frozen=True)
class FleetRow:
    """What one bag gave: a row of the table and of ``fleet.csv``.

    Estimates, their std and the truth are in :data:`PARAMS` order (m [kg], I_yy [kg m²],
    l_f [m]); a full car's in :data:`FULL_PARAMS` order (then I_xx [kg m²], y_c [m]).
    ``warnings`` sums up what went wrong short of failing, ``error`` why a bag failed.
    """

    bag: str
    status: str
    model: str = "half"  # the replayed estimator's: half or full
    duration_s: float | None = None
    updates: int = 0
    published: int = 0
    failed_updates: int = 0
    warned_updates: int = 0
    estimate: tuple[float, ...] | None = None
    std: tuple[float, ...] | None = None
    truth: tuple[float, ...] | None = None
    warnings: str = ""
    error: str = ""
    out_dir: str = ""
    plot: str = ""
    wall_s: float = 0.0

    @classmethod
    def from_result(cls, bag: Path, result: ReplayResult, wall_s: float) -> FleetRow:
        updates = [ru.update for ru in result.updates]
        published = [u for u in updates if u.published]
        failed = sum(1 for u in updates if not u.published and u.level != OK)
        warned = sum(1 for u in published if u.level != OK)
        last = published_estimate(published[-1]) if published else None
        notes = [f"{failed} updates failed"] if failed else []
        notes += [f"{warned} warned"] if warned else []
        notes += [f"{result.resets} window resets"] if result.resets else []
        dropped = sum(result.dropped.values())
        notes += [f"{dropped} samples dropped"] if dropped else []
        notes += [f"salvaged ({len(result.damage)} damaged)"] if result.damage else []
        notes += ["no recorded configuration"] if "recorded in the bag" not in result.config_source else []
        if not published and updates:
            notes.append(f"last: {LEVEL_NAMES[updates[-1].level]} {updates[-1].message}")
        return cls(
            bag=str(bag),
            status="ok" if published else ("no estimate" if updates else "failed"),
            model=result.config.model,
            duration_s=result.duration_s,
            updates=len(updates),
            published=len(published),
            failed_updates=failed,
            warned_updates=warned,
            estimate=_ordered(last.params) if last is not None and last.params is not None else None,
            std=_ordered(last.std) if last is not None and last.std is not None else None,
            truth=_ordered(result.truth) if result.truth is not None else None,
            warnings="; ".join(notes),
            error="" if updates else f"no update fell due ({result.accel_messages} accelerometer messages)",
            out_dir=str(result.out_dir or ""),
            plot=str(result.plot or ""),
            wall_s=wall_s,
        )


def _ordered(values: Any) -> tuple[float, ...]:
    """The half car's three values as they are, the full car's five (m, I_xx, I_yy, l_f, y_c)
    in :data:`FULL_PARAMS` order (m, I_yy, l_f, I_xx, y_c)."""
    picked = list(values) if len(values) == 3 else [values[0], values[2], values[3], values[1], values[4]]
    return tuple(float(v) for v in picked)


def is_bag(path: Path) -> bool:
    """A bag file, or a directory holding ``metadata.yaml`` or bag files."""
    if path.is_file():
        return path.suffix in BAG_SUFFIXES
    return path.is_dir() and (
        (path / "metadata.yaml").is_file() or any(p.suffix in BAG_SUFFIXES for p in path.iterdir())
    )


def find_bags(paths: Sequence[Path]) -> list[Path]:
    """The bags to replay: each path that is a bag (or not a directory: its row will say
    what it is), and every bag under a directory that is not one, in name order.

    Args:
        paths: the command line's.

    Returns:
        The bags, in the order given.
    """
    out: list[Path] = []
    for path in paths:
        if is_bag(path) or not path.is_dir():
            out.append(path)
            continue
        found = sorted(p for p in path.rglob("*") if is_bag(p) and not any(is_bag(q) for q in p.parents))
        out.extend(found or [path])
    return out


def replay_task(task: FleetTask) -> FleetRow:
    """Replay one bag (in a worker process, a Dask worker or here); never raises."""
    from rozyn_estimator.tools.study.work import one_blas_thread

    one_blas_thread()
    started = time.perf_counter()
    try:
        result = replay_bag(task.bag, task.out_dir, task.options)
    except Exception as exc:  # a damaged or foreign bag, or a bug: one row, the others go on
        text = str(exc) if isinstance(exc, BagError | ValueError) else f"{type(exc).__name__}: {exc}"
        return FleetRow(str(task.bag), "failed", error=" ".join(text.split()), out_dir=str(task.out_dir),
                        wall_s=time.perf_counter() - started)
    return FleetRow.from_result(task.bag, result, time.perf_counter() - started)


def plan(bags: Sequence[Path], out: Path, options: ReplayOptions) -> list[FleetTask]:
    """One task per bag, each into ``out/<bag name>`` (``-2``, ``-3`` … when names repeat)."""
    tasks, used = [], set()
    for bag in bags:
        name = bag.stem if bag.is_file() else bag.name
        unique, k = name, 2
        while unique in used:
            unique, k = f"{name}-{k}", k + 1
        used.add(unique)
        tasks.append(FleetTask(bag, out / unique, options))
    return tasks


def run_fleet(bags: Sequence[Path], args: argparse.Namespace) -> int:
    """Replay ``bags`` in parallel, print the table, write ``fleet.csv``.

    Args:
        bags: the bags (:func:`find_bags`).
        args: ``rozyn replay``'s parsed options.

    Returns:
        1 if any bag failed, else 0.

    Raises:
        BagError: the output directory holds a fleet replay already.
        ConfigError: the Dask scheduler cannot be reached.
    """
    out = Path(args.out) if args.out else Path("out", "replay", f"fleet-{utc()}")
    if (out / FLEET_CSV).exists():
        raise BagError(f"{out} holds a fleet replay already; choose another --out")
    options = ReplayOptions.from_args(args)
    check_options(options)  # a bad option fails once, not once per bag
    tasks = plan(bags, out, options)
    progress = not args.quiet and sys.stderr.isatty()
    started = time.perf_counter()
    rows = list(_dask_rows(tasks, args.scheduler, progress) if args.scheduler
                else _local_rows(tasks, args.jobs, progress))
    out.mkdir(parents=True, exist_ok=True)
    write_fleet_csv(out / FLEET_CSV, rows)
    failed = sum(r.status == "failed" for r in rows)
    if not args.quiet:
        print(format_table(rows))
        print(f"\n{len(rows)} bags in {time.perf_counter() - started:.1f} s "
              f"({args.scheduler or 'local processes'}): {len(rows) - failed} replayed, {failed} failed; "
              f"wrote {out / FLEET_CSV}")
    if failed:
        print(f"rozyn replay: {failed} of {len(rows)} bags failed (see the table)", file=sys.stderr)
    return 1 if failed else 0


def _local_rows(tasks: Sequence[FleetTask], jobs: int | None, progress: bool) -> Iterator[FleetRow]:
    from rozyn_estimator.tools.trial.run import parallel_map

    yield from parallel_map(replay_task, tasks, jobs, progress, "bag")


def _dask_rows(tasks: Sequence[FleetTask], address: str, progress: bool) -> list[FleetRow]:
    """The rows in task order, computed on the cluster's workers (as they finish)."""
    from distributed import as_completed
    from tqdm import tqdm

    from rozyn_estimator.tools.study.work import connect_scheduler

    client = connect_scheduler(address)
    rows: dict[int, FleetRow] = {}
    try:
        futures = client.map(replay_task, tasks, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        with tqdm(total=len(tasks), unit="bag", disable=not progress, leave=False, file=sys.stderr) as bar:
            for future in as_completed(futures, loop=client.loop):
                i = index[future.key]
                try:
                    rows[i] = future.result()
                except Exception as exc:  # the worker died: that bag fails, the others go on
                    rows[i] = FleetRow(str(tasks[i].bag), "failed", error=f"{type(exc).__name__}: {exc}")
                bar.update(1)
    finally:
        client.close()
    return [rows[i] for i in range(len(tasks))]


def csv_columns(params: Sequence[str]) -> tuple[str, ...]:
    """The header of ``fleet.csv`` for ``params`` (:data:`PARAMS` or :data:`FULL_PARAMS`)."""
    return ("bag", "status", "duration_s", "updates", "published", "failed_updates", "warned_updates",
            *params, *(f"{p}_std" for p in params), *(f"truth_{p}" for p in params),
            "warnings", "error", "out_dir", "plot", "wall_s")


CSV_COLUMNS = csv_columns(PARAMS)  # a fleet of half-car bags
FULL_CSV_COLUMNS = csv_columns(FULL_PARAMS)  # a fleet with a full-car bag


def _params(rows: Sequence[FleetRow]) -> tuple[str, ...]:
    """The parameters a fleet shows: the full car's five when it holds a full-car bag."""
    return FULL_PARAMS if any(r.model == "full" for r in rows) else PARAMS


def write_fleet_csv(path: Path, rows: Sequence[FleetRow]) -> None:
    """``fleet.csv``: :data:`CSV_COLUMNS` (:data:`FULL_CSV_COLUMNS` with a full-car bag), one
    row per bag (numbers at full precision; a half-car row has no roll inertia, no lateral CoG)."""
    params = _params(rows)
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, csv_columns(params))
        writer.writeheader()
        for row in rows:
            cells = {k: v for k, v in asdict(row).items() if k not in ("model", "estimate", "std", "truth")}
            for key, prefix, suffix in (("estimate", "", ""), ("std", "", "_std"), ("truth", "truth_", "")):
                values = getattr(row, key) or ()
                cells |= {f"{prefix}{p}{suffix}": values[i] if i < len(values) else None
                          for i, p in enumerate(params)}
            writer.writerow({k: _cell(v) for k, v in cells.items()})


def _cell(v: Any) -> Any:
    return repr(float(v)) if isinstance(v, float) else ("" if v is None else v)


# per parameter of FULL_PARAMS: the table's heading, width and decimals
_TABLE = (("m [kg]", 16, 1), ("I_yy [kg m²]", 17, 1), ("l_f [m]", 17, 4), ("I_xx [kg m²]", 17, 1),
          ("y_c [m]", 17, 4))


def format_table(rows: Sequence[FleetRow], width: int = 70) -> str:
    """The summary table: bag, duration, last estimate ± std, status, warnings (or the error);
    with a full-car bag, its roll inertia and lateral CoG too ("–" in a half car's row)."""
    columns = _TABLE[: len(_params(rows))]
    head = (f"{'bag':<28} {'duration':>9}  " + " ".join(f"{h:>{w}}" for h, w, _ in columns)
            + f"  {'status':<11} warnings")
    lines = [head, "-" * len(head)]
    for r in rows:
        name = Path(r.bag).name or r.bag
        name = name if len(name) <= 28 else "…" + name[-27:]
        duration = f"{r.duration_s:8.1f}s" if r.duration_s is not None else f"{'–':>9}"
        values = r.estimate or ()
        std = r.std or (float("nan"),) * len(values)
        cells = []
        for k, (_, w, d) in enumerate(columns):
            text = f"{values[k]:.{d}f} ± {std[k]:.{d}f}" if k < len(values) else "–"
            cells.append(f"{text:>{w}}")
        note = r.error.replace(r.bag, Path(r.bag).name) if r.status == "failed" else r.warnings
        note = note if len(note) <= width else note[: width - 1] + "…"
        lines.append(f"{name:<28} {duration}  {' '.join(cells)}  {r.status:<11} {note}")
    return "\n".join(lines)
