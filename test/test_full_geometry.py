"""The full car's spectrum's derivatives in its wheelbase and tracks (the first-order budget's
geometry) against central differences of the model with the vehicle moved."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rozyn_estimator.method.vehicle_fit.spectrum import VehicleSpectrum
from rozyn_estimator.method.vehicle_fit.uncertainty.geometry import GEOMETRY, geometry_derivatives
from rozyn_estimator.vehicle_full import FullVehicle

BARS = {"anti_roll_stiffness_front_nmprad": 20000.0, "anti_roll_stiffness_rear_nmprad": 8000.0}


def _model(sensors: tuple[int, ...], speed: float | np.ndarray, bars: bool) -> VehicleSpectrum:
    v = dataclasses.replace(FullVehicle(), **(BARS if bars else {}))
    return VehicleSpectrum(v, sensors, np.linspace(0.5, 15.0, 600), 100.0, speed, grid_hz=0.05,
                           kernel_m2_hz2=1e-4, road_max_cpm=5.0)


@pytest.mark.parametrize("sensors, speed, bars", [
    ((0, 1, 2, 3), 25.0, True),
    ((0, 1, 3), np.linspace(20.0, 30.0, 3000), True),  # a varying speed: the delays' distribution
    ((0, 1, 2, 3), 12.0, False),
])
def test_the_geometry_derivatives_are_the_models_change(sensors, speed, bars):
    model = _model(sensors, speed, bars)
    theta = model.theta(np.array([1500.0, 500.0, 2000.0, 1.2, 0.02]), 1e-4, np.full(len(sensors), 1e-6))
    theta[model.index["ln_coherence_scale"]] = 0.3
    theta[model.index["waviness"]] = 2.2
    analytic = geometry_derivatives(model, theta, GEOMETRY)
    h = 1e-5
    for g, key in enumerate(GEOMETRY):
        ends = []
        for sign in (1.0, -1.0):
            moved = dataclasses.replace(model.vehicle, **{key: getattr(model.vehicle, key) + sign * h})
            with model.assuming(moved):
                ends.append(model.node_spectrum(theta, derivatives=False)[0])
        numeric = (ends[0] - ends[1]) / (2.0 * h)
        assert np.abs(numeric).max() > 0
        assert np.abs(analytic[g] - numeric).max() < 1e-7 * np.abs(numeric).max(), key


def test_only_the_geometry_has_geometry_derivatives():
    model = _model((0, 1, 2, 3), 25.0, False)
    theta = model.theta(np.array([1500.0, 500.0, 2000.0, 1.2, 0.0]), 1e-4, np.full(4, 1e-6))
    with pytest.raises(ValueError, match="not a geometry value"):
        geometry_derivatives(model, theta, ["suspension_stiffness_front"])
