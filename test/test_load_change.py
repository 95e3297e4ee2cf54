"""A load change at a stop: the loaded body (sim_node.load_change), the simulator switching to it
and its truth with it, and the tools that take it."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle
from sim_node.load_change import with_point_load
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation

STOP_S = 140.0  # UDDS stands from 125 s to 164 s


@pytest.mark.parametrize("vehicle", [Vehicle(), FullVehicle(cog_lateral_m=0.03)], ids=["half", "full"])
def test_a_point_load_moves_the_cog_and_adds_its_parallel_axes(vehicle):
    loaded = with_point_load(vehicle, 150.0, 0.6)
    m, lf, i = vehicle.sprung_mass_kg, vehicle.cog_from_front_axle_m, vehicle.pitch_inertia_kgm2
    assert loaded.sprung_mass_kg == 1150.0
    assert loaded.sprung_mass_kg * loaded.cog_from_front_axle_m == pytest.approx(m * lf + 150.0 * (lf + 0.6))
    # the same body about the front axle: the load's m x² adds to the body's
    about_axle = loaded.pitch_inertia_kgm2 + loaded.sprung_mass_kg * loaded.cog_from_front_axle_m**2
    assert about_axle == pytest.approx(i + m * lf**2 + 150.0 * (lf + 0.6) ** 2)
    if isinstance(vehicle, FullVehicle):  # on the centreline of the CoG: roll stays
        assert (loaded.roll_inertia_kgm2, loaded.cog_lateral_m) == (vehicle.roll_inertia_kgm2, 0.03)
    unloaded = with_point_load(loaded, -150.0, lf + 0.6 - loaded.cog_from_front_axle_m)  # taken out again
    assert (unloaded.cog_from_front_axle_m, unloaded.pitch_inertia_kgm2) == pytest.approx((lf, i))


@pytest.mark.parametrize(("changes", "words"), [
    ({"load_change_kg": 150.0, "load_change_at_s": 140.0}, "never stops: give a drive_cycle_file"),
    ({"load_change_kg": 150.0, "load_change_at_s": 100.0, "drive_cycle_file": "udds"},
     r"drives at .* m/s at t = 100 s; a load changes at a stop \(the cycle udds stops at t = 125"),
    ({"load_change_kg": -1000.0, "load_change_at_s": STOP_S, "drive_cycle_file": "udds"},
     "takes more than the sprung mass"),
    ({"load_change_kg": 500.0, "load_change_x_m": 5.0, "load_change_at_s": STOP_S,
      "drive_cycle_file": "udds"}, "off the wheelbase"),
])
def test_a_load_change_that_cannot_happen_is_refused_with_the_reason(changes, words):
    with pytest.raises(ConfigError, match=words):
        SimConfig(**changes)


def _run(cfg: SimConfig, cuts: list[int]) -> tuple[np.ndarray, Simulation]:
    sim = Simulation(cfg)
    return np.vstack([sim.next_block(n).accel_mps2 for n in cuts]), sim


def test_the_simulator_switches_to_the_loaded_body_at_the_stop_and_its_truth_with_it():
    base = {"drive_cycle_file": "udds", "road": RoadSpec(amplitudes="gaussian"), "seed": 5}
    cfg = SimConfig(load_change_kg=150.0, load_change_x_m=0.6, load_change_at_s=STOP_S, **base)
    whole, sim = _run(cfg, [22_000])
    assert sim.truth == with_point_load(Vehicle(), 150.0, 0.6)
    cut, _ = _run(cfg, [5_000, 9_001, 7_999])  # a block boundary off the change: the same run
    np.testing.assert_array_equal(cut, whole)
    before = Simulation(cfg)
    before.next_block(13_999)
    assert before.truth == Vehicle()
    # driving on after the stop, the run is the loaded vehicle's (from rest at the stop, as the
    # loaded vehicle from the start nearly is after 15 s of standing), and not the unloaded one's
    loaded, _ = _run(SimConfig(vehicle=with_point_load(Vehicle(), 150.0, 0.6), **base), [22_000])
    unloaded, _ = _run(SimConfig(**base), [22_000])
    after = slice(17_000, 22_000)  # 170-220 s: driving again
    scale = np.std(whole[after])
    assert np.max(np.abs(whole[after] - loaded[after])) < 1e-3 * scale
    assert np.max(np.abs(whole[after] - unloaded[after])) > 0.05 * scale


def test_a_trial_with_a_load_change_is_scored_against_the_loaded_vehicle():
    spec = TrialSpec(drive_cycle="udds", duration_s=300.0, load_change_kg=150.0, load_change_x_m=0.6,
                     load_change_at_s=STOP_S, amplitudes="gaussian")
    loaded = with_point_load(Vehicle(), 150.0, 0.6)
    np.testing.assert_allclose(spec.truth, [1150.0, loaded.pitch_inertia_kgm2, loaded.cog_from_front_axle_m])
    assert spec.replace(duration_s=100.0).truth[0] == 1000.0  # the run ends before the stop
    assert spec.sim_config(1).load_change_kg == 150.0
