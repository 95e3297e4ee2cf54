"""The full car's sensors as the data may calibrate them: each sensor's gain, its position's
departures along and across the body, and the rear sensors' delay behind the front ones.

Values are departures from the vehicle file's (a log gain, metres, seconds), in one flat
layout per group (:data:`GROUPS`): ``k`` log gains, ``k`` x and ``k`` y departures, one delay.
A model's sensing ``iω f P`` (:meth:`~.spectrum.FullCarSpectrum.sensing_of`: ``f`` a channel's
factor, ``P``'s rows ``(1, -x, y)``) becomes

    g_i e^{-iωτ r_i} (iω f_i) (1, -(x_i + dx_i), y_i + dy_i),

``r_i`` 1 for a rear sensor. As ``P``'s first column is 1, ``iω f_i`` is the sensing's own
first column: the departures need nothing but the sensing itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

GROUPS = ("gain", "x", "y", "delay")
DELAY_SCALE_S = 1e-3  # the delay's parameter is in ms (of the order of the other values' scales)
_POSITION_ROWS = {"x": np.array([0.0, -1.0, 0.0]), "y": np.array([0.0, 0.0, 1.0])}


def parameter_names(groups: Sequence[str], k: int) -> list[str]:
    """θ's names of the calibrated ``groups`` for ``k`` sensors."""
    names = {"gain": [f"ln_gain_{i}" for i in range(k)], "x": [f"sensor_dx_{i}" for i in range(k)],
             "y": [f"sensor_dy_{i}" for i in range(k)], "delay": ["delay_ms"]}
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


def calibrated(sensing: np.ndarray, omega: np.ndarray, rear: np.ndarray,
               values: dict[str, np.ndarray]) -> np.ndarray:
    """(F, k, 3) the sensing with the sensors' departures ``values`` (:func:`unpack`)."""
    moved = sensing + sensing[:, :, :1] * _position_shift(values)[None]
    return _factor(omega, rear, values)[:, :, None] * moved


def derivatives(sensing: np.ndarray, omega: np.ndarray, rear: np.ndarray, values: dict[str, np.ndarray],
                groups: Sequence[str]) -> np.ndarray:
    """(G, F, k, 3) d(sensing)/d(each calibrated value, as :func:`parameter_names`) at
    ``values``: ``sensing`` is the uncalibrated one (as :func:`calibrated`'s)."""
    F, k, _ = sensing.shape
    factor = _factor(omega, rear, values)
    now = calibrated(sensing, omega, rear, values)
    rows: list[np.ndarray] = []
    for g in GROUPS:
        if g not in groups:
            continue
        if g == "gain":  # d/d ln g_i: sensor i's row
            rows += [_only_row(now[:, i], i, k) for i in range(k)]
        elif g == "delay":  # d/dτ[ms]: -iω τ' on the rear rows
            rows.append(-1j * DELAY_SCALE_S * omega[:, None, None] * now * rear[None, :, None])
        else:
            moving = factor * sensing[:, :, 0]  # (F, k): each sensor's g e^(-iωτ) iω f
            rows += [_only_row(moving[:, i, None] * _POSITION_ROWS[g][None], i, k) for i in range(k)]
    return np.array(rows) if rows else np.zeros((0, F, k, 3), dtype=complex)


def _position_shift(values: dict[str, np.ndarray]) -> np.ndarray:
    """(k, 3) the rows added to ``P``: ``(0, -dx, dy)``."""
    dx, dy = values["x"], values["y"]
    return np.column_stack([np.zeros_like(dx), -dx, dy])


def _factor(omega: np.ndarray, rear: np.ndarray, values: dict[str, np.ndarray]) -> np.ndarray:
    """(F, k) each channel's gain and delay."""
    delay = np.exp(-1j * np.outer(omega, rear * values["delay"][0]))
    return np.exp(values["gain"])[None, :] * delay


def _only_row(row: np.ndarray, i: int, k: int) -> np.ndarray:
    """(F, k, 3) zeros but sensor ``i``'s row ``row`` (F, 3)."""
    out = np.zeros((row.shape[0], k, 3), dtype=complex)
    out[:, i] = row
    return out
