"""The simulator's departures from the estimator's model (issue 10): plant, sensors, trials."""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import pytest
from scipy.signal import freqz_sos
from scipy.stats import skew

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.online import EstimatorConfig
from rozyn_estimator.parameters import build, flatten
from rozyn_estimator.tools.compare import command as compare
from rozyn_estimator.tools.demo import command as demo
from rozyn_estimator.tools.trial import command as trial_command
from rozyn_estimator.tools.trial.report import departure_lines
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.vehicle import Vehicle
from sim_node.departures import Departures, SuspensionLaw
from sim_node.fixed_point import solve_fixed_point
from sim_node.road import RoadSpec
from sim_node.sensors import GRAVITY_MPS2, Accelerometers
from sim_node.simulation import SimConfig, Simulation
from sim_node.vehicle_plant import VehiclePlant, static_state

GAUSSIAN = RoadSpec(amplitudes="gaussian")
EVERYTHING = Departures(damper_ratio=2.0, spring_progression=1.0, spring_reference_m=0.03,
                        gain_error_front=0.03, gain_error_rear=-0.02, time_offset_s=0.0053, lowpass_hz=20.0)


# ------------------------------------------------------------------ off: today's run, bit for bit
@pytest.mark.parametrize("changes", [
    {}, {"road": GAUSSIAN, "seed": 3, "noise_std_mps2": 0.05, "bias_mps2": (0.2, -0.3)},
    {"road": RoadSpec(kind="flat"), "include_gravity": False}, {"rate_hz": 400.0, "speed_variation": 0.1},
])
def test_every_departure_off_is_the_linear_run_bit_for_bit(changes):
    """Default departures take the plant's and the sensors' linear paths: the run equals the
    same plant driven by hand with the operations of the simulator before departures."""
    cfg = SimConfig(duration_s=30.0, **changes)
    sim = Simulation(cfg)
    block = sim.run(30.0)
    ref = Simulation(cfg)  # its road and settled plant, then the old sensor arithmetic by hand
    steps = ref._step + np.arange(block.accel_mps2.shape[0] * cfg.oversample)
    accel = ref.plant.run(ref._road_at(steps))[:: cfg.oversample] + np.asarray(cfg.bias_mps2)
    if cfg.include_gravity:
        accel = accel + GRAVITY_MPS2
    if cfg.noise_std_mps2 > 0:
        accel = accel + cfg.noise_std_mps2 * np.random.default_rng([cfg.seed, 2]).standard_normal(accel.shape)
    assert np.array_equal(block.accel_mps2, accel)
    assert sim.plant.iterations == 0 and not sim.plant._delayed


# ------------------------------------------------------------------ the plant's departures
def test_asymmetric_damper_law_keeps_the_mean_damping():
    law = SuspensionLaw(stiffness_npm=(45e3, 80e3), damping_nspm=(2800.0, 3500.0), damper_ratio=2.0)
    c = np.array([2800.0, 3500.0])
    rebound = law.tension_n(np.zeros(2), np.ones(2))  # extending at 1 m/s
    compression = -law.tension_n(np.zeros(2), -np.ones(2))
    assert rebound / compression == pytest.approx([2.0, 2.0])
    assert (rebound + compression) / 2 == pytest.approx(c)
    assert law.extra_tension_n(np.zeros(2), np.ones(2)) == pytest.approx(c / 3)  # a c |v|, a = 1/3


def test_progressive_spring_law():
    law = SuspensionLaw(stiffness_npm=(45e3, 80e3), damping_nspm=(1.0, 1.0), progression=0.5,
                        reference_m=0.04)
    e = np.array([[0.04, -0.04], [0.01, 0.0]])
    force = law.tension_n(e, np.zeros(2))
    assert force[0] == pytest.approx([1.5 * 45e3 * 0.04, -1.5 * 80e3 * 0.04])  # (1 + p) x linear at e_ref
    assert force[1, 0] == pytest.approx(45e3 * 0.01 * (1 + 0.5 / 16))
    assert Departures().suspension(SimConfig().vehicle) is None


class _Recording(SuspensionLaw):
    """The law, keeping the corners' motion of its last evaluation (the fixed point's)."""

    def extra_tension_n(self, extension_m, velocity_mps):
        object.__setattr__(self, "motion", (np.array(extension_m), np.array(velocity_mps)))
        return super().extra_tension_n(extension_m, velocity_mps)


def test_stiffer_rebound_jacks_the_body_down(vehicle):
    """The mean tension is zero at rest, so a mean damper tension a c E|v| > 0 (rebound
    stiffer) is balanced by the spring: E[e] = -a c E|v| / k, the body sits lower."""
    law = _Recording(stiffness_npm=(45e3, 80e3), damping_nspm=(2800.0, 3500.0), damper_ratio=2.0)
    sim = Simulation(SimConfig(road=GAUSSIAN, duration_s=60.0, seed=2))
    road = sim._road_at(np.arange(30_000))
    x0 = static_state(vehicle, road[0])
    VehiclePlant(vehicle, sim.plant.dt_s, x0=x0, u0=road[0], suspension=law).run(road)
    e, v = (m[5000:] for m in law.motion)  # after 10 s
    expected = -(1 / 3) * np.array([2800.0, 3500.0]) * np.abs(v).mean(axis=0) / np.array([45e3, 80e3])
    assert np.all(expected < -3e-4)  # about half a millimetre
    assert e.mean(axis=0) == pytest.approx(expected, rel=0.05)


def _skew_front(ratio: float) -> float:
    cfg = SimConfig(road=GAUSSIAN, duration_s=60.0, seed=1, include_gravity=False,
                    departures=Departures(damper_ratio=ratio))
    return float(skew(Simulation(cfg).run(60.0).accel_mps2[:, 0]))


def test_stiffer_rebound_skews_the_body_acceleration_down():
    """A rebound pulls the body down harder than a compression pushes it up: on the same
    road the body's acceleration skews negative with c_r > c_c and positive with c_r < c_c
    (measured: -0.14 and +0.14 against the linear damper)."""
    linear = _skew_front(1.0)
    assert _skew_front(2.0) - linear < -0.05
    assert _skew_front(0.5) - linear > 0.05


def test_blocks_cut_anywhere_give_the_same_run_with_every_departure():
    cfg = SimConfig(road=GAUSSIAN, duration_s=20.0, seed=3, noise_std_mps2=0.05, departures=EVERYTHING)
    whole = Simulation(cfg).run(20.0).accel_mps2
    sim = Simulation(cfg)
    parts = np.vstack([sim.next_block(n).accel_mps2 for n in (1, 0, 2, 497, 1, 1499)])
    assert sim.plant.iterations > 1
    assert np.max(np.abs(parts - whole)) < 1e-10  # the fixed point's tolerance; the signal is ~1 m/s^2


def test_a_suspension_that_does_not_converge_is_refused(vehicle):
    law = Departures(spring_progression=10.0, spring_reference_m=0.001).suspension(vehicle)
    plant = VehiclePlant(vehicle, 0.002, suspension=law)
    with pytest.raises(ConfigError, match="departures: the nonlinear suspension did not converge"):
        plant.run(np.column_stack([np.linspace(0, 0.05, 500)] * 2))
    with pytest.raises(ConfigError, match="did not converge"):  # diverging to overflow on the way
        Simulation(SimConfig(departures=Departures(spring_progression=10.0, spring_reference_m=0.003)))


def test_fixed_point_accelerates_where_plain_iteration_diverges():
    a = np.diag([-1.5, 0.5, 0.9])  # spectral radius 1.5: x <- a x + b diverges
    b = np.array([1.0, 2.0, 3.0])
    solved = solve_fixed_point(lambda x: (a @ x + b, None), np.zeros(3), rtol=1e-12, atol=0.0,
                               max_evaluations=20, failure="linear")
    assert solved.x == pytest.approx(np.linalg.solve(np.eye(3) - a, b), rel=1e-10)
    with pytest.raises(ConfigError, match=r"plain \(20 evaluations, last residual"):
        solve_fixed_point(lambda x: (a @ x + b, None), np.zeros(3), rtol=1e-12, atol=0.0, max_evaluations=20,
                          failure="plain", depth=0)


# ------------------------------------------------------------------ the sensors' departures
def test_gains_multiply_the_specific_force_exactly():
    plain = SimConfig(duration_s=20.0, seed=2, bias_mps2=(0.1, -0.2))
    gained = SimConfig(duration_s=20.0, seed=2, bias_mps2=(0.1, -0.2),
                       departures=Departures(gain_error_front=0.03, gain_error_rear=-0.02))
    a = Simulation(plain).run(20.0).accel_mps2 - np.array([0.1, -0.2])  # the specific force
    b = Simulation(gained).run(20.0).accel_mps2 - np.array([0.1, -0.2])
    assert np.allclose(b, a * np.array([1.03, 0.98]), rtol=1e-14, atol=1e-13)


def _smooth_road(t: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(5)
    w = 2 * np.pi * rng.uniform(0.5, 15.0, 12)
    phase = rng.uniform(0, 2 * np.pi, (12, 2))
    return (0.004 * np.sin(w[None, :, None] * t[:, None, None] + phase) / np.sqrt(w[None, :, None])).sum(1)


@pytest.mark.parametrize(("delay_s", "refine"), [(0.005, 2), (0.0033, 20), (0.004, 1)])
@pytest.mark.parametrize("channel", [0, 1])
def test_time_offset_is_exact(vehicle, delay_s, refine, channel):
    """A delayed channel at step k is the undelayed output at t_k - delay, exactly: checked
    against a plant ``refine`` times finer on the same piecewise-linear road, which has a
    step at every t_k - delay; the other channel is untouched."""
    dt, n = 0.002, 3000
    t = np.arange(n) * dt
    road = _smooth_road(t)
    x0 = static_state(vehicle, road[0])
    delays = (delay_s, 0.0) if channel == 0 else (0.0, delay_s)
    cuts = ((0, 1), (1, 2), (2, 1000), (1000, n))  # the delay's history carries over between blocks
    plant = VehiclePlant(vehicle, dt, x0=x0, u0=road[0], delays_s=delays)
    late = np.vstack([plant.run(road[a:b]) for a, b in cuts])
    plant = VehiclePlant(vehicle, dt, x0=x0, u0=road[0])
    on_time = np.vstack([plant.run(road[a:b]) for a, b in cuts])
    fine_t = np.arange((n - 1) * refine + 1) * (dt / refine)
    fine_road = np.column_stack([np.interp(fine_t, t, road[:, i]) for i in (0, 1)])
    fine = VehiclePlant(vehicle, dt / refine, x0=x0, u0=road[0]).run(fine_road)
    shift = round(delay_s / dt * refine)
    expected = fine[np.arange(n) * refine - shift][shift:]
    got = late[shift:]
    assert np.max(np.abs(got[:, channel] - expected[:, channel])) < 1e-10 * np.max(np.abs(expected))
    assert np.array_equal(late[:, 1 - channel], on_time[:, 1 - channel])


def test_time_offset_sign_picks_the_late_sensor():
    assert Departures(time_offset_s=0.005).delays_s == (0.0, 0.005)
    assert Departures(time_offset_s=-0.002).delays_s == (0.002, 0.0)


def test_time_offset_shifts_the_cross_spectrum_phase():
    """Through the whole simulation: the rear channel of a run 5 ms late against the same
    run on time has e^{-i 2 pi f tau} in their cross-spectrum (sampled at the plant's 500 Hz,
    above the road's highest frequency at 100 km/h: no aliasing; 2e-4 rad left to the
    record's ends)."""
    base = SimConfig(road=GAUSSIAN, duration_s=60.0, seed=4, include_gravity=False, rate_hz=500.0)
    a = Simulation(base).run(60.0).accel_mps2
    b = Simulation(dataclasses.replace(base, departures=Departures(time_offset_s=0.005))).run(60.0).accel_mps2
    assert np.array_equal(a[:, 0], b[:, 0])
    f = np.fft.rfftfreq(a.shape[0], 1.0 / 500.0)
    cross = np.fft.rfft(b[:, 1]) * np.conj(np.fft.rfft(a[:, 1]))
    band = (f > 0.5) & (f < 20.0)
    assert np.max(np.abs(np.angle(cross[band] * np.exp(2j * np.pi * f[band] * 0.005)))) < 1e-3


@pytest.mark.parametrize("freq_hz", [2.0, 10.0, 20.0, 40.0])
def test_lowpass_frequency_response(freq_hz):
    """The 2nd-order Butterworth at 20 Hz run at 500 Hz: a sine comes out at the digital
    filter's response exactly, -3 dB at the cutoff, within 1 % of the analog prototype's
    1/sqrt(1 + (f/fc)^4) up to the cutoff and 3 % at twice it (the bilinear transform's
    warping); streaming in blocks."""
    fs, fc = 500.0, 20.0
    sensors = Accelerometers(Departures(lowpass_hz=fc), fs, (0.0, 0.0), include_gravity=False)
    t = np.arange(int(10 * fs)) / fs
    x = np.column_stack([np.sin(2 * np.pi * freq_hz * t), np.cos(2 * np.pi * freq_hz * t)])
    y = np.vstack([sensors.lowpass(x[a:b]) for a, b in ((0, 7), (7, 2000), (2000, x.shape[0]))])
    tail = slice(int(5 * fs), None)  # after the start's transient
    response = (y[tail, 0] @ x[tail, 0] + 1j * y[tail, 0] @ x[tail, 1]) / (x[tail, 0] @ x[tail, 0])
    digital = freqz_sos(sensors._sos, worN=[freq_hz], fs=fs)[1][0]
    assert abs(response - digital) < 1e-3 * abs(digital)
    analog = 1.0 / np.sqrt(1.0 + (freq_hz / fc) ** 4)
    assert abs(response) == pytest.approx(analog, rel=0.01 if freq_hz <= fc else 0.04)
    if freq_hz == fc:
        assert abs(response) == pytest.approx(np.sqrt(0.5), rel=1e-3)


def test_lowpass_in_the_run_is_settled_and_leaves_gravity():
    cfg = SimConfig(road=GAUSSIAN, duration_s=30.0, seed=2, departures=Departures(lowpass_hz=5.0))
    filtered = Simulation(cfg).run(30.0).accel_mps2
    plain = Simulation(SimConfig(road=GAUSSIAN, duration_s=30.0, seed=2)).run(30.0).accel_mps2
    assert filtered.mean(axis=0) == pytest.approx([GRAVITY_MPS2] * 2, abs=0.01)
    assert np.all(filtered.std(axis=0) < 0.9 * plain.std(axis=0))  # the wheel hop is gone


# ------------------------------------------------------------------ configuration
def test_departures_are_sim_node_parameters():
    names = {f.name: f for f in flatten(SimConfig())}
    for field in ("damper_ratio", "spring_progression", "spring_reference_m", "gain_error_front",
                  "gain_error_rear", "time_offset_s", "lowpass_hz"):
        assert names[f"departures.{field}"].spec.read_only
    cfg = build(SimConfig(), {"departures.damper_ratio": 2, "departures.time_offset_s": 0.005})
    assert cfg.departures == Departures(damper_ratio=2.0, time_offset_s=0.005)


@pytest.mark.parametrize(("make", "match"), [
    (lambda: Departures(damper_ratio=0.0), r"departures.damper_ratio: must lie in \[0.2, 5\]"),
    (lambda: Departures(time_offset_s=0.5), "departures.time_offset_s"),
    (lambda: Departures(spring_reference_m=0.0), "departures.spring_reference_m: must lie in"),
    (lambda: SimConfig(departures=Departures(lowpass_hz=600.0)), "departures: lowpass_hz must stay below"),
    (lambda: TrialSpec(departures=Departures(lowpass_hz=510.0)), "departures: lowpass_hz"),
])
def test_invalid_departures(make, match):
    with pytest.raises(ConfigError, match=match):
        make()


# ------------------------------------------------------------------ trials: the estimator is told, or not
def test_wrong_values_reach_the_estimators_vehicle_only():
    spec = TrialSpec(tyre_stiffness_error=0.1, tyre_damping_error=-0.5, unsprung_mass_error=0.15,
                     departures=Departures(damper_ratio=2.0))
    told, true = spec.estimator_vehicle, spec.vehicle
    assert told.tyre_stiffness_front_npm == pytest.approx(1.1 * true.tyre_stiffness_front_npm)
    assert told.tyre_stiffness_rear_npm == pytest.approx(1.1 * true.tyre_stiffness_rear_npm)
    assert told.tyre_damping_rear_nspm == pytest.approx(0.5 * true.tyre_damping_rear_nspm)
    assert told.unsprung_mass_front_kg == pytest.approx(1.15 * true.unsprung_mass_front_kg)
    assert told.unsprung_mass_rear_kg == pytest.approx(1.15 * true.unsprung_mass_rear_kg)
    assert told.suspension_stiffness_front_npm == true.suspension_stiffness_front_npm
    sim = spec.sim_config(1)
    assert sim.vehicle == true and sim.departures == spec.departures
    departed = TrialSpec(departures=EVERYTHING)
    assert departed.estimator_vehicle is departed.vehicle  # the estimator is not told


def _parse(add_arguments, argv):
    p = argparse.ArgumentParser()
    add_arguments(p)
    return p.parse_args(argv)


ARGV = ["--damper-ratio", "2", "--spring-progression", "0.5", "--spring-reference-m", "0.04", "--gain-error",
        "0.03", "0", "--time-offset-s", "0.005", "--lowpass-hz", "20", "--tyre-stiffness-error", "0.1",
        "--unsprung-mass-error", "-0.13", "--tyre-damping-error", "0.2", "--stiffness-error", "0.05",
        "--damping-error", "-0.1"]


def test_trial_and_compare_options_build_the_spec():
    expected = Departures(damper_ratio=2.0, spring_progression=0.5, spring_reference_m=0.04,
                          gain_error_front=0.03, time_offset_s=0.005, lowpass_hz=20.0)
    for spec in (trial_command.trial_spec(_parse(trial_command.add_arguments, ARGV)),
                 compare.base_spec(_parse(compare.add_arguments, ARGV))):
        assert spec.departures == expected
        errors = (spec.tyre_stiffness_error, spec.unsprung_mass_error, spec.tyre_damping_error)
        assert errors == (0.1, -0.13, 0.2)
        assert (spec.stiffness_error, spec.damping_error) == (0.05, -0.1)
    plain = trial_command.trial_spec(_parse(trial_command.add_arguments, []))
    assert plain.departures == Departures() and plain.estimator_vehicle is plain.vehicle
    lines = departure_lines(spec.departures, spec.told_errors)
    assert "rear sensor +5 ms late" in lines[0] and "tyre stiffness +10 %" in lines[1]


def test_the_demo_runs_a_departing_vehicle_and_tells_the_estimator_wrong_values():
    """``rozyn demo``'s departure options reach the simulator, its error options the estimator."""
    p = argparse.ArgumentParser()
    demo.add_arguments(p)
    args = p.parse_args(["--damper-ratio", "2", "--time-offset-s", "0.005", "--tyre-stiffness-error", "0.1"])
    estimator, sim = demo.node_values(args)
    sim_cfg = build(SimConfig(), {k: v for k, v in sim.items() if k.startswith("departures.")})
    assert sim_cfg.departures == Departures(damper_ratio=2.0, time_offset_s=0.005)
    told = EstimatorConfig.from_parameters(estimator).vehicle
    assert told.tyre_stiffness_front_npm == pytest.approx(1.1 * Vehicle().tyre_stiffness_front_npm)
    assert told.suspension_stiffness_front_npm == Vehicle().suspension_stiffness_front_npm
    with pytest.raises(ConfigError, match="damper_ratio"):
        demo.node_values(p.parse_args(["--damper-ratio", "-1"]))
