"""Drive cycles: a speed trace the simulated vehicle follows instead of a constant speed.

A cycle is a CSV of time and speed (``time_s`` and one of ``speed_kmh``, ``speed_mps``,
``speed_mph``; lines starting ``#`` are comments), and past its end the cycle starts again (a
30-minute urban drive is the urban cycle repeated). The vehicle follows the rows through a
moving average over :data:`SMOOTHING_S`: a cycle's rows are targets a second apart, and
joining them by straight lines would step the acceleration every second (an unbounded jerk)
and pitch the body harder than a driver does; averaged, the acceleration is continuous and
the jerk at most a row's change of acceleration per second. Speed, distance and acceleration
are exact for that average (the rows joined linearly, then averaged).

Shipped, by name (``sim_node/drive_cycles/``, each citing its public source): ``udds`` (US EPA
urban, stop-and-go), ``hwfet`` (US EPA highway) and ``wltc3b`` (the UN's worldwide cycle, class 3b).
"""

from __future__ import annotations

import csv
import functools
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rozyn_estimator.errors import ConfigError

SHIPPED_DIR = Path(__file__).with_name("drive_cycles")
SHIPPED = ("udds", "hwfet", "wltc3b")
_UNITS = {"speed_mps": 1.0, "speed_kmh": 1.0 / 3.6, "speed_mph": 0.44704}
MAX_CYCLE_SPEED_MPS = 150.0  # the estimator drops faster speeds as corrupt (online.config)
_MAX_BYTES = 16 << 20
SMOOTHING_S = 1.0  # the driver's moving average over the cycle's rows (see the module's docstring)


@dataclass(frozen=True)
class DriveCycle:
    """A speed trace: ``speed_mps`` at ``time_s`` (from 0, increasing), linear in between."""

    name: str
    time_s: np.ndarray
    speed_mps: np.ndarray

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1])

    @property
    def length_m(self) -> float:
        """The distance one pass of the cycle covers."""
        return float(self._cumulative[-1])

    # The rows' tables, made once: every simulated block reads them (the rows do not change).
    @functools.cached_property
    def _cumulative(self) -> np.ndarray:
        """The distance [m] at each row."""
        return np.concatenate(([0.0], np.cumsum(np.diff(self.time_s) * 0.5 * (self.speed_mps[1:]
                                                                              + self.speed_mps[:-1]))))

    @functools.cached_property
    def _slopes(self) -> np.ndarray:
        """The acceleration [m/s²] between rows."""
        return np.diff(self.speed_mps) / np.diff(self.time_s)

    @functools.cached_property
    def _integrals(self) -> np.ndarray:
        """``∫_0`` of the linear distance [m s] up to each row."""
        d0, dt = self._cumulative, np.diff(self.time_s)
        v, a = self.speed_mps[:-1], self._slopes
        return np.concatenate(([0.0], np.cumsum(d0[:-1] * dt + v * dt**2 / 2 + a * dt**3 / 6)))

    def _linear_distance(self, t: np.ndarray) -> np.ndarray:
        """The distance [m] from t = 0 of the rows joined linearly (exact: quadratic between rows)."""
        laps, local = np.divmod(t, self.duration_s)
        k, tau = self._piece(local)
        within = self.speed_mps[k] * tau + 0.5 * self._slopes[k] * tau * tau
        return laps * self.length_m + self._cumulative[k] + within

    def _distance_integral(self, t: np.ndarray) -> np.ndarray:
        """``∫_0^t`` of :meth:`_linear_distance` [m s]: cubic between rows, laps in closed form."""
        laps, local = np.divmod(t, self.duration_s)
        k, tau = self._piece(local)
        d0, pieces = self._cumulative, self._integrals
        within = d0[k] * tau + self.speed_mps[k] * tau**2 / 2 + self._slopes[k] * tau**3 / 6
        one_lap, length = pieces[-1], self.length_m
        # laps before: each a lap's integral plus the distance of the laps before it
        return (laps * one_lap + length * self.duration_s * laps * (laps - 1) / 2
                + pieces[k] + within + laps * length * local)

    def _piece(self, local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = np.clip(np.searchsorted(self.time_s, local, side="right") - 1, 0, self.time_s.size - 2)
        return k, local - self.time_s[k]

    def speed_at(self, t_s: np.ndarray) -> np.ndarray:
        """The speed [m/s] at times ``t_s`` (the cycle repeated, before 0 too; averaged over
        :data:`SMOOTHING_S`)."""
        t = np.asarray(t_s, dtype=float)
        return (self._linear_distance(t) - self._linear_distance(t - SMOOTHING_S)) / SMOOTHING_S

    def acceleration_at(self, t_s: np.ndarray) -> np.ndarray:
        """The longitudinal acceleration [m/s²] at times ``t_s``: the speed's exact derivative."""
        t = np.asarray(t_s, dtype=float)
        linear = np.interp(np.mod(t, self.duration_s), self.time_s, self.speed_mps)
        before = np.interp(np.mod(t - SMOOTHING_S, self.duration_s), self.time_s, self.speed_mps)
        return (linear - before) / SMOOTHING_S

    def distance_at(self, t_s: np.ndarray) -> np.ndarray:
        """The distance [m] driven from t = 0 (negative before it): the exact integral of
        :meth:`speed_at`."""
        t = np.asarray(t_s, dtype=float)
        moving = self._distance_integral(t) - self._distance_integral(t - SMOOTHING_S)
        return (moving - self._zero) / SMOOTHING_S

    @functools.cached_property
    def _zero(self) -> float:
        return float(self._distance_integral(np.array(0.0)) - self._distance_integral(np.array(-SMOOTHING_S)))

    def standing_share(self, threshold_mps: float = 0.5) -> float:
        """The share of the cycle's time below ``threshold_mps`` (sampled every 0.1 s)."""
        t = np.arange(0.0, self.duration_s, 0.1)
        return float(np.mean(self.speed_at(t) < threshold_mps))


def load_drive_cycle(source: str) -> DriveCycle:
    """A shipped cycle by name (:data:`SHIPPED`) or a CSV file.

    Raises:
        ConfigError: no such cycle or file, or a file that is not a usable speed trace (the
            message names the line or the rule).
    """
    name = source.strip()
    path = SHIPPED_DIR / f"{name}.csv" if name in SHIPPED else Path(name).expanduser()
    if not path.is_file():
        raise ConfigError(f"drive cycle {source!r}: no such file (shipped cycles: {', '.join(SHIPPED)})")
    if path.stat().st_size > _MAX_BYTES:
        raise ConfigError(f"drive cycle {path}: larger than {_MAX_BYTES >> 20} MiB; a cycle is a speed trace")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"drive cycle {path}: cannot read it ({exc})") from None
    return parse_drive_cycle(text, path.stem if name not in SHIPPED else name, str(path))


def parse_drive_cycle(text: str, name: str, source: str = "drive cycle") -> DriveCycle:
    """A :class:`DriveCycle` from CSV text (see the module's docstring)."""
    rows = [r for r in csv.reader(io.StringIO(text)) if r and not r[0].lstrip().startswith("#")]
    if not rows:
        raise ConfigError(f"{source}: no header; expected time_s and one of {', '.join(_UNITS)}")
    header = [h.strip() for h in rows[0]]
    speed_col = next((h for h in header if h in _UNITS), None)
    if "time_s" not in header or speed_col is None:
        raise ConfigError(f"{source}: header {','.join(header)[:200]}; expected time_s and one of "
                          f"{', '.join(_UNITS)}")
    it, iv = header.index("time_s"), header.index(speed_col)
    t, v = [], []
    for line, row in enumerate(rows[1:], start=2):
        try:
            a, b = float(row[it]), float(row[iv])
        except (IndexError, ValueError):
            raise ConfigError(f"{source}: data row {line - 1} ({','.join(row)[:80]}) is not two "
                              "numbers") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise ConfigError(f"{source}: data row {line - 1} holds a value that is not finite")
        t.append(a)
        v.append(b * _UNITS[speed_col])
    time_s, speed = np.array(t), np.array(v)
    if time_s.size < 2 or time_s[0] != 0.0 or np.any(np.diff(time_s) <= 0):
        raise ConfigError(f"{source}: time_s must start at 0 and increase, over at least two rows")
    if np.any(speed < 0) or np.any(speed > MAX_CYCLE_SPEED_MPS):
        raise ConfigError(f"{source}: speeds must lie in 0-{MAX_CYCLE_SPEED_MPS:g} m/s")
    if not np.any(speed > 0):
        raise ConfigError(f"{source}: the vehicle never moves")
    return DriveCycle(name, time_s, speed)
