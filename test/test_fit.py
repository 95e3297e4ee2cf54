"""Inertial parameters from identified modes (thesis section 2-4): the fit on exact modes."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.method.fit import (
    characteristic_matrix,
    corner_impedances,
    corner_shapes,
    fit_inertia,
    plane_map,
)
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.vehicle import Vehicle
from sim_node.vehicle_plant import state_space

from conftest import TRUTH

OTHER = Vehicle(sprung_mass_kg=1800.0, pitch_inertia_kgm2=3200.0, cog_from_front_axle_m=1.55, wheelbase_m=3.2,
                sensor_front_offset_m=0.3, sensor_rear_offset_m=-0.4)
RAISED = OTHER.replace(cog_height_m=0.6, wheel_centre_height_m=0.32)  # gravity through the geometry


def body_modes(v: Vehicle) -> list[Mode]:
    """The two body modes of the 4-DOF half car, exactly (eigen-pairs of its state matrix),
    with their shapes at the vehicle's sensors."""
    lam, vecs = np.linalg.eig(state_space(v).a)
    keep = np.flatnonzero(lam.imag > 0)
    keep = keep[np.argsort(np.abs(lam[keep]))][:2]  # the body modes are the slow ones
    lf = v.cog_from_front_axle_m
    modes = []
    for k in keep:
        xs, phi = vecs[2, k], vecs[3, k]
        shape = np.array([xs + (lf - x) * phi for x in v.sensor_x_m])
        shape = shape / shape[np.argmax(np.abs(shape))]
        modes.append(Mode(complex(lam[k]), (complex(shape[0]), complex(shape[1])), 0.5))
    return sorted(modes, key=lambda m: m.freq_hz)


@pytest.mark.parametrize("vehicle", [Vehicle(), OTHER, RAISED], ids=["table5-1", "other", "raised"])
def test_condensed_stiffness_on_exact_modes_recovers_the_truth(vehicle):
    truth = [vehicle.sprung_mass_kg, vehicle.pitch_inertia_kgm2, vehicle.cog_from_front_axle_m]
    params = fit_inertia(vehicle, body_modes(vehicle), "condensed")
    assert params == pytest.approx(truth, rel=1e-8)


def test_the_fit_told_no_heights_reads_a_raised_car_s_inertia_high():
    """The weight through the geometry softens pitch: told nothing of it, the fit reads the
    lower pitch frequency as a larger inertia (the check above can fail)."""
    told = RAISED.replace(cog_height_m=0.0, wheel_centre_height_m=0.0)
    params = fit_inertia(told, body_modes(RAISED), "condensed")
    assert params[1] > 1.01 * RAISED.pitch_inertia_kgm2


def test_eq_2_22_is_close_and_eq_2_21_biased_on_exact_modes(vehicle):
    modes = body_modes(vehicle)
    assert fit_inertia(vehicle, modes, "eq2-22") == pytest.approx(TRUTH, rel=0.01)
    static = fit_inertia(vehicle, modes, "eq2-21")
    assert static[0] < 0.98 * TRUTH[0]  # the static stiffness (thesis) costs a few % in mass


def test_characteristic_matrix_has_the_modes_as_eigenvalues(vehicle):
    modes = body_modes(vehicle)
    poles = np.array([m.eigenvalue for m in modes])
    a0 = characteristic_matrix(poles, corner_shapes(vehicle, modes))
    assert np.sort_complex(np.linalg.eigvals(a0)) == pytest.approx(
        np.sort_complex(np.r_[poles, poles.conj()]), rel=1e-9)


def test_the_line_through_the_sensors_gives_the_axles():
    axles = np.array([0.3, -0.1])  # axle heaves
    L = OTHER.wheelbase_m
    sensors = np.array([[1 - x / L, x / L] for x in OTHER.sensor_x_m]) @ axles
    assert plane_map(OTHER.sensor_x_m, OTHER.sensor_y_m, OTHER) @ sensors == pytest.approx(axles)


def test_corner_impedances_static_limit_and_unknown_model(vehicle):
    kf, kr = corner_impedances(vehicle, 0.0, "condensed")
    series = [ks * kt / (ks + kt) for ks, kt in ((45_000.0, 200_000.0), (80_000.0, 200_000.0))]
    assert [kf.real, kr.real] == pytest.approx(series)
    with pytest.raises(ValueError, match="unknown stiffness model"):
        corner_impedances(vehicle, 0.0, "springy")


def test_unphysical_modes_are_refused(vehicle):
    """Shapes and frequencies no rigid body on these corners has: the CoG lands ahead of the
    front axle, and the fit says so instead of returning a number."""
    slow, fast = body_modes(vehicle)
    modes = [Mode(slow.eigenvalue, (1.0, 0.2), 0.5), Mode(5.0 * fast.eigenvalue, (0.2, 1.0), 0.5)]
    with pytest.raises(IdentificationError, match="physical range"):
        fit_inertia(vehicle, modes, "eq2-22")
