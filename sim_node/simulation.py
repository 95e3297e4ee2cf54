"""A streaming simulation run: road + speed profile + half car + accelerometers.

``Simulation.next_block(n)`` returns the next ``n`` accelerometer samples; the state of
the plant, the distance travelled and the noise stream carry over, so a run cut into
blocks equals the same run made at once and memory stays bounded however long it runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.vehicle import Vehicle
from sim_node.halfcar import N_DOF, N_STATE, HalfCarPlant, static_state
from sim_node.road import Road, RoadSpec

GRAVITY_MPS2 = 9.80665
# Thesis' free-decay start (main listing): wheels -0.015 m, body -0.03 m, no pitch.
THESIS_FREE_DECAY_STATE = (-0.015, -0.015, -0.03, 0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class SimConfig:
    """One simulated run. Lengths in m, times in s, accelerations in m/s^2."""

    vehicle: Vehicle = field(default_factory=Vehicle)
    road: RoadSpec = field(default_factory=RoadSpec)
    seed: int = 0
    speed_kmh: float = 100.0
    speed_variation: float = 0.0  # relative amplitude of a sinusoidal speed change
    speed_period_s: float = 60.0
    rate_hz: float = 100.0  # accelerometer output rate
    min_internal_rate_hz: float = 500.0  # plant step rate is the next multiple of rate_hz
    noise_std_mps2: float = 0.0  # white sensor noise, per channel
    bias_mps2: tuple[float, float] = (0.0, 0.0)  # constant sensor offsets (front, rear)
    include_gravity: bool = True  # REP 145: a level accelerometer at rest reads +g
    settle_s: float = 5.0  # driven before t = 0 so the run starts stationary
    duration_s: float = 0.0  # 0: endless (sizes the road only)
    initial_state: tuple[float, ...] | None = None  # free decay start; flat roads only

    def __post_init__(self) -> None:
        checks = {
            "speed_kmh": 0.0 < self.speed_kmh <= 400.0,
            "speed_variation": 0.0 <= self.speed_variation < 1.0,
            "speed_period_s": self.speed_period_s > 0.0,
            "rate_hz": 1.0 <= self.rate_hz <= 100_000.0,
            "min_internal_rate_hz": self.min_internal_rate_hz > 0.0,
            "noise_std_mps2": self.noise_std_mps2 >= 0.0,
            "settle_s": self.settle_s >= 0.0,
            "duration_s": self.duration_s >= 0.0,
        }
        for name, ok in checks.items():
            value = getattr(self, name)
            if not (ok and math.isfinite(float(value))):
                raise ConfigError(f"sim.{name}: invalid value {value!r}")
        if len(self.bias_mps2) != 2 or not all(math.isfinite(b) for b in self.bias_mps2):
            raise ConfigError(f"sim.bias_mps2: expected two finite numbers, got {self.bias_mps2!r}")
        if self.initial_state is not None and len(self.initial_state) != N_STATE:
            raise ConfigError(f"sim.initial_state: expected {N_STATE} numbers, got {len(self.initial_state)}")

    @property
    def speed_mps(self) -> float:
        return self.speed_kmh / 3.6

    @property
    def oversample(self) -> int:
        """Plant steps per output sample."""
        return max(1, math.ceil(self.min_internal_rate_hz / self.rate_hz - 1e-9))


@dataclass(frozen=True)
class SimBlock:
    """Consecutive accelerometer samples of a run."""

    t_s: np.ndarray  # (n,) time since the run started
    accel_mps2: np.ndarray  # (n, 2) front/rear vertical specific force
    speed_mps: np.ndarray  # (n,) vehicle speed


class Simulation:
    """A run of the half car over a road, produced block by block."""

    def __init__(self, config: SimConfig) -> None:
        self.config = config
        cfg = config
        self._dt = 1.0 / (cfg.rate_hz * cfg.oversample)
        self._wheelbase = cfg.vehicle.wheelbase_m
        period = None
        if cfg.duration_s > 0:  # one road period per record, as the thesis' eq 4-7
            period = float(np.diff(self.distance_m(np.array([0.0, cfg.duration_s])))[0])
        self.road = Road(cfg.road, cfg.seed, period_m=period)
        self._noise = np.random.default_rng([cfg.seed, 2])
        self._step = -round(cfg.settle_s / self._dt) if cfg.road.kind != "flat" else 0
        u0 = self._road_at(np.array([self._step]))[0]
        if cfg.initial_state is not None:
            x0 = np.asarray(cfg.initial_state, dtype=float)
        elif cfg.road.kind == "flat":
            x0 = np.asarray(THESIS_FREE_DECAY_STATE)
        else:
            x0 = static_state(cfg.vehicle, u0)
        self.plant = HalfCarPlant(cfg.vehicle, self._dt, x0=x0, u0=u0)
        if self._step < 0:
            self._advance(-self._step)

    @property
    def time_s(self) -> float:
        """Time of the next sample [s]."""
        return self._step * self._dt

    def distance_m(self, t_s: np.ndarray) -> np.ndarray:
        """Distance the rear axle has travelled at ``t_s``, from the road's origin [m]."""
        cfg = self.config
        t = np.asarray(t_s, dtype=float) + cfg.settle_s
        s = cfg.speed_mps * t
        if cfg.speed_variation:
            w = 2.0 * np.pi / cfg.speed_period_s
            s = s + cfg.speed_mps * cfg.speed_variation * (1.0 - np.cos(w * t)) / w
        return s

    def speed_at(self, t_s: np.ndarray) -> np.ndarray:
        cfg = self.config
        t = np.asarray(t_s, dtype=float) + cfg.settle_s
        w = 2.0 * np.pi / cfg.speed_period_s
        return cfg.speed_mps * (1.0 + cfg.speed_variation * np.sin(w * t))

    def _road_at(self, steps: np.ndarray) -> np.ndarray:
        """(n, 2) front/rear road height at plant steps."""
        s_rear = self.distance_m(steps * self._dt)
        return np.column_stack(
            [self.road.heights(s_rear + self._wheelbase), self.road.heights(s_rear)]
        )

    def _advance(self, n_steps: int) -> np.ndarray:
        steps = self._step + np.arange(n_steps)
        accel = self.plant.run(self._road_at(steps))
        self._step += n_steps
        return accel

    def next_block(self, n: int) -> SimBlock:
        """The next ``n`` accelerometer samples."""
        cfg = self.config
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n}")
        t = self.time_s + np.arange(n) / cfg.rate_hz
        accel = self._advance(n * cfg.oversample)[:: cfg.oversample]
        accel = accel + np.asarray(cfg.bias_mps2)
        if cfg.include_gravity:
            accel = accel + GRAVITY_MPS2
        if cfg.noise_std_mps2 > 0:
            accel = accel + cfg.noise_std_mps2 * self._noise.standard_normal((n, 2))
        return SimBlock(t_s=t, accel_mps2=accel, speed_mps=self.speed_at(t))

    def run(self, duration_s: float) -> SimBlock:
        """The next ``duration_s`` of samples in one block."""
        return self.next_block(round(duration_s * self.config.rate_hz))


__all__ = ["GRAVITY_MPS2", "N_DOF", "SimBlock", "SimConfig", "Simulation"]
