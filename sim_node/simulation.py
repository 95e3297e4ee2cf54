"""A streaming simulation run: road + speed profile + half (or full) car + accelerometers.

``Simulation.next_block(n)`` returns the next ``n`` accelerometer samples; the state of
the plant, the distance travelled, the sensors' filters and the noise stream carry over,
so a run cut into blocks equals the same run made at once and memory stays bounded
however long it runs. ``SimConfig.departures`` makes the plant and the sensors depart
from the estimator's model (:mod:`sim_node.departures`); by default they do not. Where the
speed varies and the vehicle gives its CoG's height, accelerating and braking pitch the body
(:mod:`sim_node.load_transfer`).

``SimConfig.model = "full"`` runs the 7-DOF full car (:mod:`sim_node.vehicle_plant`) of
``full_vehicle`` over two road tracks (:mod:`sim_node.tracks`, coherence
``track_coherence``): the blocks then carry four accelerometer channels in the order FL,
FR, RL, RR (``SimBlock.channels``) at the vehicle's ``sensor_x_m``/``sensor_y_m``, and the
truth is ``SimConfig.plant_vehicle``. Of the departures the full car takes only the
sensors' low-pass; the half car stays the default and its runs are unchanged.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rozyn_estimator.body_model import (
    pitch_index,
    second_order_model,
    sensor_rates,
    sensor_rows,
    suspension_rows,
)
from rozyn_estimator.errors import ConfigError
from rozyn_estimator.parameters import check, param
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import MODELS, FullVehicle
from sim_node.departures import Departures, per_channel
from sim_node.drive_cycle import DriveCycle, load_drive_cycle
from sim_node.load_change import STANDING_MPS, with_point_load
from sim_node.load_transfer import LoadTransfer
from sim_node.road import Road, RoadSpec
from sim_node.sensors import GRAVITY_MPS2, Accelerometers
from sim_node.tracks import COHERENCES, RoadTracks
from sim_node.vehicle_plant import VehiclePlant, n_state, static_state

# Thesis' free-decay start (main listing): wheels -0.015 m, body -0.03 m, no pitch.
THESIS_FREE_DECAY_STATE = (-0.015, -0.015, -0.03, 0.0, 0.0, 0.0, 0.0, 0.0)
FULL_FREE_DECAY_STATE = (-0.015,) * 4 + (-0.03,) + (0.0,) * 9  # the same for the full car: no roll
HALF_CHANNELS = ("front", "rear")


@dataclass(frozen=True)
class SimConfig:
    """One simulated run. Lengths in m, times in s, accelerations in m/s^2.

    The described fields with a ROS name are ``sim_node``'s parameters of the same names.
    """

    PARAM_PREFIX: ClassVar[str] = ""

    vehicle: Vehicle = param(description="the vehicle (vehicle.* parameters)", default_factory=Vehicle)
    road: RoadSpec = param(description="the road (road.* parameters)", default_factory=RoadSpec)
    seed: int = param(0, "random seed of the road and the noise", low=0, high=2**31 - 1, read_only=True)
    speed_kmh: float = param(100.0, "vehicle speed", unit="km/h", low=1.0, high=400.0, read_only=True)
    speed_variation: float = param(0.0, "relative amplitude of a sinusoidal speed change", low=0.0,
                                   ros_name="")
    speed_period_s: float = param(60.0, "period of the speed change", unit="s", low=0.0, open_low=True,
                                  ros_name="")
    drive_cycle_file: str = param("", "drive cycle the vehicle follows instead of speed_kmh: a shipped one "
                                  "(udds, hwfet, wltc3b) or a CSV of time_s and speed_kmh (or speed_mps, "
                                  "speed_mph), repeated; empty: constant speed", read_only=True)
    load_change_kg: float = param(0.0, "a point load put in (negative: taken out) at load_change_at_s, "
                                  "on the centreline at the CoG's height; 0: none", unit="kg", low=-1e5,
                                  high=1e5, read_only=True)
    load_change_x_m: float = param(0.0, "where that load sits behind the centre of gravity (negative: "
                                   "ahead of it)", unit="m", low=-10.0, high=10.0, read_only=True)
    load_change_at_s: float = param(0.0, "when the load changes: the vehicle must stand then (a stop of the "
                                    "drive cycle)", unit="s", low=0.0, high=1e9, read_only=True)
    rate_hz: float = param(100.0, "accelerometer rate", unit="Hz", low=1.0, high=100_000.0, read_only=True)
    # 1 kHz: the plant holds the road linear over a step; at 500 Hz that hold's images, aliased
    # into the sensors' band, were what the estimator's model check saw on quiet sensors
    min_internal_rate_hz: float = param(1000.0, "the plant's step rate is the next multiple of rate_hz "
                                        "from this", unit="Hz", low=0.0, open_low=True, ros_name="")
    noise_std_mps2: float = param(0.0, "white sensor noise per channel", unit="m/s^2", low=0.0, high=100.0,
                                  read_only=True)
    gyro_noise_std_radps: float = param(0.0, "white noise of a gyro channel (a vehicle's sensors block)",
                                        unit="rad/s", low=0.0, high=10.0, read_only=True)
    gyro_bias_radps: float = param(0.0, "constant offset of a gyro channel", unit="rad/s", low=-10.0,
                                   high=10.0, read_only=True)
    bias_mps2: tuple[float, float] = param((0.0, 0.0), "constant sensor offsets (front, rear)", unit="m/s^2",
                                           length=2, ros_name="")
    include_gravity: bool = param(True, "REP 145: a level accelerometer at rest reads +g", ros_name="")
    settle_s: float = param(5.0, "driven before t = 0 so the run starts stationary", unit="s", low=0.0,
                            ros_name="")
    duration_s: float = param(0.0, "simulated time to run; 0: forever (a finite run's road period is its "
                              "distance)", unit="s", low=0.0, high=1e9, read_only=True)
    initial_state: tuple[float, ...] | None = None  # free decay start; flat roads only
    departures: Departures = param(description="departures from the estimator's model (departures.* "
                                   "parameters)", default_factory=Departures)
    model: str = param("half", "vehicle model: half (4-DOF, accelerometers front and rear) or full (7-DOF, "
                       "four accelerometers FL, FR, RL, RR)", choices=MODELS, ros_name="")
    full_vehicle: FullVehicle | None = None  # the full car (model full; None: its defaults)
    track_coherence: str = param("isotropic", "coherence of the left and right road tracks (model full)",
                                 choices=COHERENCES, ros_name="")

    def __post_init__(self) -> None:
        check(self, (
            ("speed_variation", lambda c: c.speed_variation < 1.0, "must lie in [0, 1)"),
            ("speed_variation", lambda c: c.speed_variation == 0.0 or not c.drive_cycle_file,
             "a drive cycle sets the speed: speed_variation must be 0 with drive_cycle_file"),
            ("initial_state", lambda c: c.initial_state is None or len(c.initial_state) == c.n_state,
             f"expected {n_state(Vehicle())} numbers ({n_state(FullVehicle())} with model full)"),
            ("departures", lambda c: c.departures.lowpass_hz < 0.5 * c.rate_hz * c.oversample,
             "lowpass_hz must stay below the plant's Nyquist frequency, rate_hz * oversample / 2"),
            ("full_vehicle", lambda c: c.full_vehicle is None or (c.model == "full" and isinstance(
                c.full_vehicle, FullVehicle)), "is the full car's: a FullVehicle, with model full"),
            ("vehicle", lambda c: c.model == "half" or c.vehicle == Vehicle(),
             "is the half car's; with model full the plant is full_vehicle"),
            ("departures", lambda c: c.model == "full" or c.departures.corner_gain_errors == (0.0,) * 4,
             "corner_gain_errors are the full car's (model full); the half car's are gain_error_front/rear"),
            ("bias_mps2", lambda c: c.model == "half" or c.bias_mps2 == (0.0, 0.0),
             "the full car's accelerometers take no bias: must be (0, 0) with model full"),
        ))
        try:
            self.drive_cycle  # noqa: B018 (loaded and checked now, not at the first step)
        except ConfigError as exc:
            raise ConfigError(f"drive_cycle_file: {exc}") from None
        if self.load_change_kg:
            self._check_load_change()

    def _check_load_change(self) -> None:
        """ConfigError unless the load changes while the vehicle stands, to a vehicle."""
        cycle, at = self.drive_cycle, self.load_change_at_s
        if cycle is None:
            raise ConfigError("load_change_kg: a load changes at a stop, and at a constant speed the vehicle "
                              "never stops: give a drive_cycle_file")
        speed = float(cycle.speed_at(np.array([at]))[0])
        if speed >= STANDING_MPS:
            t = np.arange(0.0, cycle.duration_s, 0.5)
            stops = t[(cycle.speed_at(t) < STANDING_MPS) & (cycle.speed_at(t - 0.5) >= STANDING_MPS)]
            near = ", ".join(f"{x:g}" for x in stops[np.argsort(np.abs(stops - at % cycle.duration_s))[:3]])
            raise ConfigError(f"load_change_at_s: the vehicle drives at {speed:.1f} m/s at t = {at:g} s; a "
                              f"load changes at a stop (the cycle {cycle.name} stops at t = {near} s, among "
                              "others)")
        with_point_load(self.plant_vehicle, self.load_change_kg, self.load_change_x_m)

    @property
    def speed_mps(self) -> float:
        return self.speed_kmh / 3.6

    @functools.cached_property
    def drive_cycle(self) -> DriveCycle | None:
        """The drive cycle ``drive_cycle_file`` names (None: constant speed); ConfigError if unusable."""
        return load_drive_cycle(self.drive_cycle_file) if self.drive_cycle_file else None

    @property
    def plant_vehicle(self) -> Vehicle | FullVehicle:
        """The simulated vehicle (the truth): ``vehicle``, or with model full ``full_vehicle``."""
        if self.model == "full":
            return self.full_vehicle if self.full_vehicle is not None else FullVehicle()
        return self.vehicle

    @property
    def channels(self) -> tuple[str, ...]:
        """The channels, in the order of a block's columns: the accelerometers, or a sensors
        block's channels (``imu.accel_z``, ``imu.gyro_y``)."""
        return self.plant_vehicle.channel_names

    @property
    def gyros(self) -> np.ndarray:
        """(channels,) bool: which channels are gyros."""
        return sensor_rates(self.plant_vehicle)

    @property
    def n_state(self) -> int:
        """Length of the plant's physical state ``[q, q']``."""
        return n_state(self.plant_vehicle)

    @property
    def oversample(self) -> int:
        """Plant steps per output sample."""
        return max(1, math.ceil(self.min_internal_rate_hz / self.rate_hz - 1e-9))


@dataclass(frozen=True)
class SimBlock:
    """Consecutive accelerometer samples of a run."""

    t_s: np.ndarray  # (n,) time since the run started
    accel_mps2: np.ndarray  # (n, channels) vertical specific force: front/rear, or FL, FR, RL, RR
    speed_mps: np.ndarray  # (n,) vehicle speed
    channels: tuple[str, ...] = HALF_CHANNELS  # the columns of accel_mps2


def gyro_mixing(vehicle: Vehicle | FullVehicle, yaw_rad: float) -> np.ndarray | None:
    """(k, k) what each channel reads of the body's: the gyros of each sensor with both turned
    ``yaw_rad`` about z (None: not turned). ConfigError where a turned sensor lacks one."""
    if yaw_rad == 0.0:
        return None
    chans = vehicle.channels if isinstance(vehicle, FullVehicle) and vehicle.sensors is not None else ()
    mix = np.eye(len(chans))
    for sensor in {c.sensor for c in chans if c.kind != "accel_z"}:
        kinds = {c.kind: i for i, c in enumerate(chans) if c.sensor == sensor}
        if not {"gyro_x", "gyro_y"} <= set(kinds):
            raise ConfigError(f"gyro_yaw_misalignment_rad: {sensor} needs both gyro_x and gyro_y to turn")
        x, y = kinds["gyro_x"], kinds["gyro_y"]
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        mix[x, x], mix[x, y], mix[y, x], mix[y, y] = c, s, -s, c
    if not chans or np.array_equal(mix, np.eye(len(chans))):
        raise ConfigError("gyro_yaw_misalignment_rad: only a full car's sensors block with gyro_x and gyro_y "
                          "has gyros to turn")
    return mix


class Simulation:
    """A run of the half car (or the full car) over a road, produced block by block."""

    def __init__(self, config: SimConfig) -> None:
        self.config = config
        cfg = config
        self._dt = 1.0 / (cfg.rate_hz * cfg.oversample)
        vehicle = cfg.plant_vehicle
        self._wheelbase = vehicle.wheelbase_m
        period = None
        if cfg.duration_s > 0:  # one road period per record, as the thesis' eq 4-7
            period = float(np.diff(self.distance_m(np.array([0.0, cfg.duration_s])))[0])
        self.tracks: RoadTracks | None = None
        if isinstance(vehicle, FullVehicle):
            self.tracks = RoadTracks(cfg.road, cfg.seed, vehicle.track_front_m, period_m=period,
                                     coherence=cfg.track_coherence)
            self.road = self.tracks.left  # the half car's road of this seed
        else:
            self.road = Road(cfg.road, cfg.seed, period_m=period)
        self._noise = np.random.default_rng([cfg.seed, 2])
        self._step = -round(cfg.settle_s / self._dt) if cfg.road.kind != "flat" else 0
        self.truth = vehicle  # the simulated vehicle now (a load change replaces it)
        self._change_step = round(cfg.load_change_at_s / self._dt) if cfg.load_change_kg else None
        u0 = self._road_at(np.array([self._step]))[0]
        self._build_plants(vehicle, self._initial_state(u0), u0)
        gyros = cfg.gyros
        accel_bias = per_channel(cfg.bias_mps2, gyros.size)  # the full car's: zero
        bias = tuple(np.where(gyros, cfg.gyro_bias_radps, accel_bias))
        self.sensors = Accelerometers(cfg.departures, 1.0 / self._dt, bias, cfg.include_gravity,
                                      full_car=isinstance(vehicle, FullVehicle), gyros=gyros)
        self._noise_std = np.where(gyros, cfg.gyro_noise_std_radps, cfg.noise_std_mps2)
        self._mix = gyro_mixing(vehicle, cfg.departures.gyro_yaw_misalignment_rad)
        if self._step < 0:
            self._advance(-self._step)

    def _build_plants(self, vehicle: Vehicle | FullVehicle, x0: np.ndarray, u0: np.ndarray) -> None:
        """The plant of ``vehicle`` from state ``x0`` on the road ``u0``, and its load transfer."""
        cfg = self.config
        # a load change keeps the sensors: the loaded vehicle is built on the configured one
        self.plant = VehiclePlant(vehicle, self._dt, x0=x0, u0=u0,
                                  suspension=cfg.departures.suspension(vehicle), delays_s=self._delays_s())
        self._transfer = self._load_transfer(vehicle)

    def _change_load(self) -> None:
        """The load changes now (the vehicle stands): the loaded body at rest on the road here."""
        cfg = self.config
        self.truth = with_point_load(self.truth, cfg.load_change_kg, cfg.load_change_x_m)
        u0 = self._road_at(np.array([self._step]))[0]
        rest = static_state(self.truth, u0)
        self._build_plants(self.truth, rest, u0)

    def _load_transfer(self, vehicle: Vehicle | FullVehicle) -> LoadTransfer | None:
        """The body's pitch from accelerating and braking (:mod:`sim_node.load_transfer`) where the
        vehicle gives its CoG's height and the speed varies; else None."""
        cfg = self.config
        if vehicle.cog_height_m <= 0.0 or (cfg.drive_cycle is None and cfg.speed_variation == 0.0):
            return None
        accel0 = float(self.acceleration_at(np.array(self._step * self._dt)))
        return LoadTransfer(second_order_model(vehicle), sensor_rows(vehicle), suspension_rows(vehicle),
                            pitch_index(vehicle), vehicle.sprung_mass_kg, vehicle.cog_height_m, self._dt,
                            accel0, self._delays_s(), rates=cfg.gyros)

    def _delays_s(self) -> tuple[float, ...]:
        """Each channel's delay behind its step [s] (the departures')."""
        cfg = self.config
        delays = cfg.departures.corner_delays_s if cfg.model == "full" else cfg.departures.delays_s
        return per_channel(delays, len(cfg.channels))

    def _initial_state(self, u0: np.ndarray) -> np.ndarray:
        """The plant's start: ``initial_state``, the thesis' free decay on a flat road, else at rest."""
        cfg = self.config
        vehicle = cfg.plant_vehicle
        if cfg.initial_state is not None:
            return np.asarray(cfg.initial_state, dtype=float)
        if cfg.road.kind == "flat":
            return np.asarray(FULL_FREE_DECAY_STATE if cfg.model == "full" else THESIS_FREE_DECAY_STATE)
        return static_state(vehicle, u0)

    @property
    def time_s(self) -> float:
        """Time of the next sample [s]."""
        return self._step * self._dt

    def distance_m(self, t_s: np.ndarray) -> np.ndarray:
        """Distance the rear axle has travelled at ``t_s``, from the road's origin [m]."""
        cfg = self.config
        t = np.asarray(t_s, dtype=float) + cfg.settle_s
        if cfg.drive_cycle is not None:  # the cycle starts at t = 0; the settling drives its end
            cycle = cfg.drive_cycle
            return cycle.distance_at(t - cfg.settle_s) - cycle.distance_at(np.array(-cfg.settle_s))
        s = cfg.speed_mps * t
        if cfg.speed_variation:
            w = 2.0 * np.pi / cfg.speed_period_s
            s = s + cfg.speed_mps * cfg.speed_variation * (1.0 - np.cos(w * t)) / w
        return s

    def speed_at(self, t_s: np.ndarray) -> np.ndarray:
        cfg = self.config
        if cfg.drive_cycle is not None:
            return cfg.drive_cycle.speed_at(t_s)
        t = np.asarray(t_s, dtype=float) + cfg.settle_s
        w = 2.0 * np.pi / cfg.speed_period_s
        return cfg.speed_mps * (1.0 + cfg.speed_variation * np.sin(w * t))

    def acceleration_at(self, t_s: np.ndarray) -> np.ndarray:
        """The longitudinal acceleration [m/s²] at ``t_s``: the speed's derivative."""
        cfg = self.config
        if cfg.drive_cycle is not None:
            return cfg.drive_cycle.acceleration_at(t_s)
        t = np.asarray(t_s, dtype=float) + cfg.settle_s
        w = 2.0 * np.pi / cfg.speed_period_s
        return cfg.speed_mps * cfg.speed_variation * w * np.cos(w * t)

    def _road_at(self, steps: np.ndarray) -> np.ndarray:
        """(n, 2) front/rear road height at plant steps; the full car's (n, 4) FL, FR, RL, RR: the
        rear wheels in the front ones' tracks, a wheelbase behind."""
        s_rear = self.distance_m(steps * self._dt)
        if self.tracks is not None:
            return np.hstack([self.tracks.heights(s_rear + self._wheelbase), self.tracks.heights(s_rear)])
        return np.column_stack(
            [self.road.heights(s_rear + self._wheelbase), self.road.heights(s_rear)]
        )

    def _advance(self, n_steps: int) -> np.ndarray:
        """The body's acceleration at the sensors over the next plant steps, low-passed (the
        load changing on its step)."""
        at, end = self._change_step, self._step + n_steps
        if at is not None and self._step <= at < end:
            before = self._advance_plant(at - self._step)
            self._change_load()
            self._change_step = None
            return np.vstack([before, self._advance_plant(end - at)])
        return self._advance_plant(n_steps)

    def _advance_plant(self, n_steps: int) -> np.ndarray:
        steps = self._step + np.arange(n_steps)
        body = self.plant.run(self._road_at(steps))
        if self._transfer is not None:
            body = body + self._transfer.run(self.acceleration_at(steps * self._dt))
        accel = self.sensors.lowpass(body)
        self._step += n_steps
        return accel

    def next_block(self, n: int) -> SimBlock:
        """The next ``n`` accelerometer samples."""
        cfg = self.config
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n}")
        t = self.time_s + np.arange(n) / cfg.rate_hz
        body = self._advance(n * cfg.oversample)[:: cfg.oversample]
        accel = self.sensors.read(body if self._mix is None else body @ self._mix.T)
        if np.any(self._noise_std > 0):
            accel = accel + self._noise_std * self._noise.standard_normal((n, len(cfg.channels)))
        return SimBlock(t_s=t, accel_mps2=accel, speed_mps=self.speed_at(t), channels=cfg.channels)

    def run(self, duration_s: float) -> SimBlock:
        """The next ``duration_s`` of samples in one block."""
        return self.next_block(round(duration_s * self.config.rate_hz))


__all__ = ["GRAVITY_MPS2", "SimBlock", "SimConfig", "Simulation"]
