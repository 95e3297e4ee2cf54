"""The full car's sensors as the data may calibrate them: each sensor's gain, its position's
departures along and across the body, the rear sensors' delay behind the front ones, and
each gyro's turn about z (an IMU mounted turned: its roll gyro reads a share of the pitch
rate, its pitch gyro of the roll rate).

Values are departures from the vehicle file's (a log gain, metres, seconds, radians), in one
flat layout per group (:data:`GROUPS`): ``k`` log gains, ``k`` x and ``k`` y departures, one
delay, ``k`` turns (an accelerometer's held at 0).
A model's sensing ``iω f P`` (:meth:`~.spectrum.VehicleSpectrum.sensing_of`: ``f`` a channel's
factor, ``P``'s rows ``(1, -x, y)``) becomes

    g_i e^{-iωτ r_i} (iω f_i) (1, -(x_i + dx_i), y_i + dy_i),

``r_i`` 1 for a rear sensor. As ``P``'s first column is 1, ``iω f_i`` is the sensing's own
first column: the departures need nothing but the sensing itself. A gyro's row ``P`` (its
rate, ``f`` without ``iω``) turned by ``ψ`` gains ``ψ f T``: ``gyro_x`` reads ``ω_x + ψ ω_y``
(``T = (0, -1, 0)``), ``gyro_y`` ``ω_y - ψ ω_x`` (``T = (0, 0, -1)``), REP 103's rates (a
turn about z by ``ψ``, to first order; :class:`ChannelLayout`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rozyn_estimator.body_model import GYRO_ROWS

GROUPS = ("gain", "x", "y", "delay", "turn")
DELAY_SCALE_S = 1e-3  # the delay's parameter is in ms (of the order of the other values' scales)
_POSITION_ROWS = {"x": np.array([0.0, -1.0, 0.0]), "y": np.array([0.0, 0.0, 1.0])}
# a gyro's row P and the row T its turn adds: the other gyro's (gyro_y's turned row gains -θ')
_TURNS = {"gyro_x": (GYRO_ROWS["gyro_x"], GYRO_ROWS["gyro_y"]),
          "gyro_y": (GYRO_ROWS["gyro_y"], tuple(-x for x in GYRO_ROWS["gyro_x"]))}


@dataclass(frozen=True)
class ChannelLayout:
    """What the calibration needs of the channels besides their sensing."""

    late: np.ndarray  # (k,) 1 for a channel on the clock the delay puts late (channel_late)
    turns: np.ndarray  # (k, 2, 3) a gyro's row P and the row T its turn adds; zeros for an accelerometer


def channel_layout(late: Sequence[bool], kinds: Sequence[str]) -> ChannelLayout:
    """The layout of channels of ``kinds`` (``accel_z``, ``gyro_x``, ``gyro_y``)."""
    turns = np.array([_TURNS.get(kind, ((0.0,) * 3, (0.0,) * 3)) for kind in kinds], dtype=float)
    return ChannelLayout(np.asarray(late, dtype=float), turns.reshape(len(kinds), 2, 3))


def parameter_names(groups: Sequence[str], k: int) -> list[str]:
    """θ's names of the calibrated ``groups`` for ``k`` sensors."""
    names = {"gain": [f"ln_gain_{i}" for i in range(k)], "x": [f"sensor_dx_{i}" for i in range(k)],
             "y": [f"sensor_dy_{i}" for i in range(k)], "delay": ["delay_ms"],
             "turn": [f"gyro_turn_{i}" for i in range(k)]}
    return [name for g in GROUPS if g in groups for name in names[g]]


def unpack(values: np.ndarray, groups: Sequence[str], k: int) -> dict[str, np.ndarray]:
    """The flat ``values`` (as :func:`parameter_names`) -> each group's (k,) or (1,) values [SI]
    (log gains, m, s); zeros for the groups not calibrated."""
    out = {g: np.zeros(1 if g == "delay" else k) for g in GROUPS}
    at = 0
    for g in GROUPS:
        if g in groups:
            size = out[g].size
            out[g] = np.asarray(values[at: at + size], dtype=float)
            at += size
    out["delay"] = out["delay"] * DELAY_SCALE_S
    return out


def calibrated(sensing: np.ndarray, omega: np.ndarray, layout: ChannelLayout,
               values: dict[str, np.ndarray]) -> np.ndarray:
    """(F, k, b) the sensing with the sensors' departures ``values`` (:func:`unpack`)."""
    moved = sensing + sensing[:, :, :1] * _position_shift(values)[None, :, : sensing.shape[-1]]
    if np.any(values["turn"]):
        moved = moved + values["turn"][None, :, None] * _turning(sensing, layout)
    return _factor(omega, layout.late, values)[:, :, None] * moved


def derivatives(sensing: np.ndarray, omega: np.ndarray, layout: ChannelLayout, values: dict[str, np.ndarray],
                groups: Sequence[str]) -> np.ndarray:
    """(G, F, k, b) d(sensing)/d(each calibrated value, as :func:`parameter_names`) at
    ``values``: ``sensing`` is the uncalibrated one (as :func:`calibrated`'s)."""
    F, k, b = sensing.shape
    rear = layout.late
    factor = _factor(omega, rear, values)
    now = calibrated(sensing, omega, layout, values)
    rows: list[np.ndarray] = []
    for g in GROUPS:
        if g not in groups:
            continue
        if g == "gain":  # d/d ln g_i: sensor i's row
            rows += [_only_row(now[:, i], i, k) for i in range(k)]
        elif g == "delay":  # d/dτ[ms]: -iω τ' on the rear rows
            rows.append(-1j * DELAY_SCALE_S * omega[:, None, None] * now * rear[None, :, None])
        elif g == "turn":  # d/dψ_i: the gain and delay times f T on gyro i's row
            turning = factor[:, :, None] * _turning(sensing, layout)
            rows += [_only_row(turning[:, i], i, k) for i in range(k)]
        else:
            moving = factor * sensing[:, :, 0]  # (F, k): each sensor's g e^(-iωτ) iω f
            rows += [_only_row(moving[:, i, None] * _POSITION_ROWS[g][None, :b], i, k) for i in range(k)]
    return np.array(rows) if rows else np.zeros((0, F, k, b), dtype=complex)


def _turning(sensing: np.ndarray, layout: ChannelLayout) -> np.ndarray:
    """(F, k, b) ``f T`` per channel: a gyro's own factor (its sensing along its row P) times
    the row its turn adds; zeros for an accelerometer (and on a body that does not roll)."""
    b = sensing.shape[-1]
    own = np.einsum("fkc,kc->fk", sensing, layout.turns[:, 0, :b])
    return own[:, :, None] * layout.turns[None, :, 1, :b]


def _position_shift(values: dict[str, np.ndarray]) -> np.ndarray:
    """(k, 3) the rows added to ``P``: ``(0, -dx, dy)``."""
    dx, dy = values["x"], values["y"]
    return np.column_stack([np.zeros_like(dx), -dx, dy])


def _factor(omega: np.ndarray, rear: np.ndarray, values: dict[str, np.ndarray]) -> np.ndarray:
    """(F, k) each channel's gain and delay."""
    delay = np.exp(-1j * np.outer(omega, rear * values["delay"][0]))
    return np.exp(values["gain"])[None, :] * delay


def _only_row(row: np.ndarray, i: int, k: int) -> np.ndarray:
    """(F, k, b) zeros but sensor ``i``'s row ``row`` (F, b)."""
    out = np.zeros((row.shape[0], k, row.shape[-1]), dtype=complex)
    out[:, i] = row
    return out
