"""What each toleranced value contributes to the full car's refined estimate (GUM type B).

An assumed value ``β`` off by ``δ`` moves the likelihood's optimum by
``dθ̂ = -F⁻¹ F_θβ δ``, ``F_θβ = Σ_k tr(S⁻¹ ∂_θ S S⁻¹ ∂_β S)`` the information shared between the
fitted parameters and ``β`` (the expected score's slope in ``β``: the fit absorbs what it can
of the changed spectrum into θ, the nuisances included). ``∂_β S`` is the model's change
with the value moved a small step. Per toleranced value: that move times its tolerance,
mapped to ``(m, I_xx, I_yy, l_f, y_c)``. The keys follow the Rozyn stage's budget
(:mod:`rozyn_estimator.method.full.budget`): an axle's share applies to both its corners,
a sensor's position or gain to each sensor on its own (independent errors: one
contribution each), the time offset to the rear sensors against the front ones.

Work: ``F_θβ`` is a smooth sum over the band: it is taken over every fourth of the fit's
frequencies (each standing for its neighbours), a quarter of the model's work per value;
the contributions stay within 2 % of the every-frequency ones (tested; every eighth: 5 %;
without the aliasing terms, though they carry a few per mille of the power: 9 %).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rozyn_estimator.method.full.budget import ABS_STEP, AXLE, VehicleMove, moved_copy, vehicle_moves
from rozyn_estimator.method.full.spectrum import FullCarSpectrum
from rozyn_estimator.method.full.whittle import FullWhittle
from rozyn_estimator.vehicle_full import CORNERS, FullVehicle

_STEP = 4  # the sums over every 4th of the fit's frequencies (module docstring)

# a move: the step -> (the vehicle moved, a factor per channel (F, k) or None)
Move = Callable[[float], tuple[FullVehicle, np.ndarray | None]]


def refinement_contributions(objective: FullWhittle, theta: np.ndarray, theta_cov: np.ndarray,
                             vehicle: FullVehicle) -> dict[str, np.ndarray]:
    """Contributions ``c_j`` (5,) of each toleranced value of ``vehicle`` to the refined estimate."""
    full = objective.model
    model = full.subset(_STEP)
    S, dS = model.spectrum(theta)
    linv = np.linalg.inv(np.linalg.cholesky(S))
    counts = np.add.reduceat(objective.counts, np.arange(0, objective.counts.size, _STEP))
    weighted = FullWhittle(model, np.zeros_like(S), counts)  # the subset's sums stand for the whole band's
    assert dS is not None
    rows = weighted.whitened(linv, dS)
    jac = full.physical_jacobian(theta)
    out: dict[str, np.ndarray] = {}
    try:
        for key, tol in vehicle.tolerances.to_dict().items():
            if tol <= 0:
                continue
            for name, step, move in _moves(vehicle, model, key):
                moved, factor = move(step)
                model.set_vehicle(moved, factor)
                dS = (model.spectrum(theta, derivatives=False)[0] - S)[None] / step
                shared = (rows @ weighted.whitened(linv, dS).T)[:, 0]  # F_θβ
                out[name] = -(jac @ (theta_cov @ shared)) * tol
    finally:
        model.set_vehicle(vehicle)
    return out


def _moves(v: FullVehicle, model: FullCarSpectrum, key: str) -> list[tuple[str, float, Move]]:
    """(contribution name, step, the move) of one tolerance key: the vehicle's values as in
    Rozyn's stage's budget; each sensor's offset and gain on its own, the rear sensors' timing
    as a factor on their channels."""
    def unsensed(move: VehicleMove) -> Move:
        return lambda h: (move(h), None)

    def shifted(corner: int) -> Move:
        def move(h: float) -> tuple[FullVehicle, np.ndarray | None]:
            xs = list(v.sensor_x_m)
            xs[corner] += h
            return moved_copy(v, sensor_x_m=tuple(xs)), None
        return move

    def channel(columns: list[int], factor: Callable[[float], np.ndarray]) -> Move:
        def move(h: float) -> tuple[FullVehicle, np.ndarray | None]:
            out = np.ones((model.omega.size, model.k), dtype=complex)
            out[:, columns] = factor(h)[:, None]
            return v, out
        return move

    sensors = model.sensors
    alike = vehicle_moves(v, key, sensors)
    if alike is not None:
        return [(name, step, unsensed(move)) for name, step, move in alike]
    axle = AXLE["front" if "_front" in key else "rear"]
    if key in ("sensor_front_offset_m", "sensor_rear_offset_m"):
        return [(f"{key}[{CORNERS[c]}]", ABS_STEP, shifted(c)) for c in sensors if c in axle]
    if key.startswith("sensor_gain"):
        return [(f"{key}[{CORNERS[c]}]", ABS_STEP,
                 channel([j], lambda h: np.full(model.omega.size, 1.0 + h, dtype=complex)))
                for j, c in enumerate(sensors) if c in axle]
    if key == "sensor_time_offset_s":
        rear = [j for j, c in enumerate(sensors) if c in AXLE["rear"]]
        return [(key, ABS_STEP, channel(rear, lambda h: np.exp(-1j * model.omega * h)))]
    return []
