"""What a study computes: its grid (:class:`Cell`), its settings and the grid options' syntax.

:class:`StudySettings` is what ``study.json`` records and ``--resume`` compares; it gives
each cell's trial conditions (:class:`~rozyn_estimator.tools.trial.TrialSpec`) and each
trial's seed. Also here: the names of the files a study writes into its directory.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PipelineConfig
from rozyn_estimator.parameters import check, param
from rozyn_estimator.tools.cars import CARS, Car
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.vehicle import Vehicle, vehicle_from_mapping
from rozyn_estimator.vehicle_full import FullVehicle, full_vehicle_from_mapping

STUDY_ROADS = ("iso", "laplace")
DRIVES = ("independent", "nested")
THESIS_CELL = (100.0, 100.0)  # km/h, s: the condition of the thesis' Figs 5-3 to 5-10

# The files of a study directory.
MANIFEST = "study.json"  # the settings and a log of the runs
RESULTS = "results.csv"  # one row per trial
SUMMARY_CSV = "summary.csv"  # per cell statistics, full precision
SUMMARY_MD = "summary.md"  # the same, rounded, for reading
FIGURES = "figures"  # directory of the PNG figures


@dataclass(frozen=True, order=True)
class Cell:
    """One condition of the grid."""

    road: str
    speed_kmh: float
    duration_s: float

    @property
    def label(self) -> str:
        return f"{self.road}, {self.speed_kmh:g} km/h, {self.duration_s:g} s"


def _distinct(values: tuple[Any, ...]) -> bool:
    return len(set(values)) == len(values)


@dataclass(frozen=True)
class StudySettings:
    """What a study computes; ``study.json`` records it and ``--resume`` compares it.

    The road, sensor and method settings are checked once more as each cell's
    :class:`TrialSpec` (the first and the last cell are built here). The half car's
    ``study.json`` holds neither ``model`` nor ``full_vehicle`` (as before the full car);
    the full car's holds ``model: full`` and its car as ``vehicle``.
    """

    model: str = param("half", "vehicle model: half (front and rear accelerometers) or full (four corners, "
                       "two road tracks: roll inertia and lateral CoG too)", choices=tuple(CARS))
    roads: tuple[str, ...] = param(STUDY_ROADS, "roads of the grid: iso, laplace")
    speeds_kmh: tuple[float, ...] = param(tuple(float(v) for v in range(30, 101, 10)), "speeds of the grid",
                                          unit="km/h", low=0.0, open_low=True)
    durations_s: tuple[float, ...] = param(tuple(float(v) for v in range(10, 121, 10)),
                                           "measurement times of the grid", unit="s", low=0.0, open_low=True)
    trials: int = param(100, "random roads per cell", low=1)
    amplitudes: str = param("fixed", "fixed: the thesis' road generator; gaussian: a true Gaussian road",
                            choices=("fixed", "gaussian"))
    road_class: str = param("A", "ISO 8608 class of the base road, A..H")
    laplace_nu: float = param(1.0, "Laplace road: variance of the section gamma variable")
    rate_hz: float = param(100.0, "accelerometer rate", unit="Hz")
    noise_std_mps2: float = param(0.0, "white sensor noise", unit="m/s^2")
    noise_fraction: float = param(0.0, "white sensor noise as a share of each channel's rms (0.1: 10 %)",
                                  low=0.0)
    method: str = param("", "estimation method; empty: the model's default_method()", choices=tuple(METHODS))
    seed_base: int = param(0, "changes every road seed", low=0)
    drives: str = param("", "independent: a drive per cell and trial (the thesis' design); nested: one drive "
                        "per road, speed and trial, estimated after each measurement time of it, each update "
                        "warm-started from the last (tools/trial/drives.py); empty: nested for a refined "
                        "method, else independent", choices=("", *DRIVES))
    vehicle: Vehicle = param(description="the half car", default_factory=Vehicle)
    full_vehicle: FullVehicle = param(description="the full car (model full)", default_factory=FullVehicle)

    def __post_init__(self) -> None:
        if not self.method and self.model in CARS:  # an unknown model is refused by check()
            object.__setattr__(self, "method", default_method(self.model))
        if not self.drives and self.method in METHODS:
            object.__setattr__(self, "drives", "nested" if self.refined else "independent")
        check(self, (
            ("method", lambda s: s.method in s.car.methods,
             f"the full car has {', '.join(CARS['full'].methods)}"),
            ("roads", lambda s: bool(s.roads), "the grid needs at least one road"),
            ("roads", lambda s: all(r in STUDY_ROADS for r in s.roads),
             f"each road must be one of {', '.join(STUDY_ROADS)}"),
            ("roads", lambda s: _distinct(s.roads), "repeated values"),
            ("speeds_kmh", lambda s: bool(s.speeds_kmh), "the grid needs at least one speed"),
            ("speeds_kmh", lambda s: _distinct(s.speeds_kmh), "repeated values"),
            ("durations_s", lambda s: bool(s.durations_s), "the grid needs at least one measurement time"),
            ("durations_s", lambda s: _distinct(s.durations_s), "repeated values"),
        ))
        for cell in (self.cells()[0], self.cells()[-1]):
            self.trial_spec(cell)  # validates road, speed, duration, rate, noise

    def cells(self) -> list[Cell]:
        """The grid in its canonical order: road, then speed, then duration."""
        return [Cell(r, s, d) for r in self.roads for s in self.speeds_kmh for d in self.durations_s]

    @property
    def car(self) -> Car:
        """What the model estimates and how the study's files name it."""
        return CARS[self.model]

    @property
    def studied_vehicle(self) -> Vehicle | FullVehicle:
        """The simulated (and assumed) vehicle: the half or the full car."""
        return self.full_vehicle if self.model == "full" else self.vehicle

    def truth(self) -> np.ndarray:
        """(k,) the true parameters, in the model's order."""
        return self.car.truth(self.studied_vehicle)

    def reference(self) -> np.ndarray:
        """(k,) what the relative statistics are a share of (the truth; the lateral CoG's: the half track)."""
        return self.car.reference(self.studied_vehicle)

    @property
    def refined(self) -> bool:
        """The method refines Rozyn's estimate (its updates can start from the previous one's)."""
        return getattr(self.pipeline_config(), "refine", "none") != "none"

    @property
    def nested(self) -> bool:
        """One drive per road, speed and trial, estimated after each measurement time."""
        return self.drives == "nested"

    def drive_cell(self, road: str, speed_kmh: float) -> Cell:
        """The cell of a nested drive: the road and speed at the longest measurement time."""
        return Cell(road, speed_kmh, max(self.durations_s))

    @property
    def n_trials(self) -> int:
        return len(self.roads) * len(self.speeds_kmh) * len(self.durations_s) * self.trials

    def pipeline_config(self) -> PipelineConfig:
        """The method's settings; Rozyn's pipeline without its jackknife covariance (the study
        is the spread), a refined method as shipped (the jackknife's std scales the
        refinement's guard against wrong basins: without it every trial runs a second start)."""
        cfg = METHODS[self.method]
        if self.method == default_method():
            cfg = _without_refinement(cfg)
        return cfg if getattr(cfg, "refine", "none") != "none" else cfg.replace(variance="none")

    def trial_spec(self, cell: Cell) -> TrialSpec:
        """A cell's trial conditions (the seed picks the road)."""
        return TrialSpec(
            road=cell.road, road_class=self.road_class, amplitudes=self.amplitudes,
            laplace_nu=self.laplace_nu, speed_kmh=cell.speed_kmh, duration_s=cell.duration_s,
            rate_hz=self.rate_hz, noise_std_mps2=self.noise_std_mps2, noise_fraction=self.noise_fraction,
            vehicle=self.studied_vehicle, method=self.method, pipeline=self.pipeline_config(),
        )

    def seed(self, cell: Cell, trial: int) -> int:
        """The road seed of a trial: a function of the seed base, the cell and the trial only
        (nested drives: of the road, the speed and the trial; every measurement time of a
        drive has its seed).

        Adding cells to a grid, or running it on more workers, leaves every other trial
        as it was; ``rozyn trial --seed SEED`` with the cell's options repeats a trial (a nested
        drive's: with ``--durations-s`` the grid's times).
        """
        if self.nested:
            key = [self.seed_base, zlib.crc32(cell.road.encode()), round(cell.speed_kmh * 1000), trial]
        else:
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
        out["vehicle"] = self.studied_vehicle.to_dict()
        del out["full_vehicle"]
        if self.model == "half":
            del out["model"]
        out["pipeline"] = dataclasses.asdict(self.pipeline_config())
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> StudySettings:
        values = {k: v for k, v in data.items() if k != "pipeline"}
        try:
            if values.get("model", "half") == "full":
                values["full_vehicle"] = full_vehicle_from_mapping(values.pop("vehicle", {}), source=MANIFEST)
            else:
                values["vehicle"] = vehicle_from_mapping(values.get("vehicle", {}), source=MANIFEST)
            for name in ("roads", "speeds_kmh", "durations_s"):
                values[name] = tuple(values[name])
            values.setdefault("drives", "independent")  # a manifest from before nested drives
            return cls(**values)
        except (KeyError, TypeError) as exc:
            raise ConfigError(f"{MANIFEST}: not a study manifest this version can read ({exc})") from None


def default_method(model: str = "half") -> str:
    """The study's default method: the half car's, Rozyn's pipeline (``rozyn``), the thesis'
    subject; the full car's, ``likelihood`` (Rozyn's stage, then the likelihood refinement)."""
    return CARS[model].default_method


def _without_refinement(cfg: PipelineConfig) -> PipelineConfig:
    """The Rozyn stage of a method: no refinement after Rozyn's pipeline, if it has one."""
    return cfg.replace(refine="none") if getattr(cfg, "refine", "none") != "none" else cfg


def fmt_value(value: float) -> str:
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
            values.extend(_range(numbers[0], numbers[1], numbers[2], name=name))
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
                          f"{fmt_value(start)}:{fmt_value(stop)}:{fmt_value(step)}")
    count = math.floor((stop - start) / step + 1e-9) + 1
    return [round(start + k * step, 9) for k in range(count)]


def parse_roads(text: str) -> tuple[str, ...]:
    roads = tuple(r.strip().lower() for r in text.split(",") if r.strip())
    for road in roads:
        if road not in STUDY_ROADS:
            raise ConfigError(f"roads: unknown road {road!r}; choose from {', '.join(STUDY_ROADS)}")
    return roads
