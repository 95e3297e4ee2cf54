"""Checks the spectral model's tests share, for either car: its derivatives against central
differences, and the simulator's plant as the transfer function it must equal."""

from __future__ import annotations

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from sim_node.vehicle_plant import state_space


def assert_slopes(model: VehicleSpectrum, theta: np.ndarray, rtol: float, atol: float = 0.0) -> None:
    """Every dS/dθ of ``model`` at θ is the central difference of S (step 1e-6)."""
    _, dS = model.spectrum(theta)
    assert dS is not None
    for j, name in enumerate(model.names):
        step = np.zeros_like(theta)
        step[j] = 1e-6
        slope = (model.spectrum(theta + step, False)[0] - model.spectrum(theta - step, False)[0]) / 2e-6
        assert np.max(np.abs(slope - dS[j])) < rtol * np.max(np.abs(dS[j])) + atol, name


def plant_response(vehicle: AnyVehicle, freq_hz: np.ndarray) -> np.ndarray:
    """(F, channels, wheels) the plant's state space from the road under each wheel to the channels."""
    ss = state_space(vehicle)
    eye = np.eye(ss.a.shape[0])
    return np.array([ss.c @ np.linalg.solve(1j * w * eye - ss.a, ss.b) + ss.d for w in 2 * np.pi * freq_hz])


def model_response(model: VehicleSpectrum, theta: np.ndarray) -> np.ndarray:
    """(F, channels, wheels) the model's ``G = P D⁻¹ Bᵀ T`` per unit road velocity, times iω: per
    unit road height, as the plant's."""
    w = model.omega
    M, _ = model.body.mass_matrix(theta)
    D = model.body_stiffness + model.body.gravity_stiffness(theta) - (w**2)[:, None, None] * M
    return model.sensing @ np.linalg.solve(D, model.body_input) * (1j * w)[:, None, None]
