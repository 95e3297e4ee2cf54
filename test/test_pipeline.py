from __future__ import annotations

import json

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, LikelihoodConfig, PipelineConfig, estimate
from rozyn_estimator.method.fit import corner_impedances
from rozyn_estimator.method.modal_stage import fit_correlations
from rozyn_estimator.vehicle import Vehicle
from sim_node.road import RoadSpec
from sim_node.simulation import SimConfig, Simulation
from sim_node.vehicle_plant import state_space

from conftest import TRUTH

FREE_DECAY = dict(correlation="free-decay", variance="none", min_duration_s=0.5)


def free_decay(vehicle, duration_s=1.0):
    sim = Simulation(SimConfig(vehicle=vehicle, road=RoadSpec(kind="flat"), include_gravity=False))
    return sim.run(duration_s).accel_mps2


def test_free_decay_within_half_a_percent(vehicle):
    """Thesis section 5-1: 1002 / 2009 / 1.204; eq 2-22 must be within 0.5 %."""
    est = estimate(free_decay(vehicle), 100.0, vehicle, METHODS["rozyn"].replace(**FREE_DECAY))
    assert est.ok, est.reason
    assert np.all(np.abs(est.params / TRUTH - 1) < 0.005)
    assert [round(m.freq_hz, 2) for m in est.modes] == [1.29, 1.86]


def test_condensed_model_is_exact_and_eq_2_21_biased(vehicle):
    acc = free_decay(vehicle)
    exact = estimate(acc, 100.0, vehicle, METHODS["rozyn-condensed"].replace(**FREE_DECAY))
    assert np.all(np.abs(exact.params / TRUTH - 1) < 1e-4)
    static = estimate(acc, 100.0, vehicle, METHODS["rozyn-eq2-21"].replace(**FREE_DECAY))
    assert -0.05 < static.params[0] / 1000 - 1 < -0.03  # about -4 %, as the issue says


def test_other_vehicle_free_decay():
    v = Vehicle(sprung_mass_kg=1650.0, pitch_inertia_kgm2=2700.0, cog_from_front_axle_m=1.45,
                wheelbase_m=3.05, suspension_stiffness_front_npm=60000.0,
                suspension_stiffness_rear_npm=70000.0, unsprung_mass_front_kg=55.0)
    est = estimate(free_decay(v), 100.0, v, METHODS["rozyn-condensed"].replace(**FREE_DECAY))
    truth = np.array([1650.0, 2700.0, 1.45])
    assert np.all(np.abs(est.params / truth - 1) < 1e-3)


def exact_correlations(v: Vehicle, speed_mps: float, fs: float, n_lags: int) -> np.ndarray:
    """Correlation sums (lags, 2, 2) of the sampled accelerations under white road
    velocity, from the transfer functions (rear input delayed by wheelbase/speed)."""
    ss = state_space(v)
    fs_fine, nfft = 20 * fs, 2**17
    f = np.fft.rfftfreq(nfft, 1 / fs_fine)[1:]
    s = 2j * np.pi * f
    h_u = np.einsum("ij,fjk->fik", ss.c, np.linalg.solve(s[:, None, None] * np.eye(8) - ss.a, ss.b)) + ss.d
    h = (h_u[:, :, 0] + h_u[:, :, 1] * np.exp(-s * v.wheelbase_m / speed_mps)[:, None]) / s[:, None]
    spec = np.concatenate([np.zeros((1, 2, 2)), h[:, :, None] * h[:, None, :].conj()])
    corr = np.fft.irfft(spec, n=nfft, axis=0)
    return corr[: (n_lags + 1) * 20 : 20]


@pytest.mark.parametrize("speed_kmh", [30.0, 100.0])
def test_exact_correlations_recover_the_truth(vehicle, speed_kmh):
    """With infinite data, lags beyond the wheelbase delay are an exact free decay."""
    cfg = METHODS["rozyn-condensed"]
    speed = speed_kmh / 3.6
    first = int(np.ceil(vehicle.wheelbase_m / speed * 100))
    corr = exact_correlations(vehicle, speed, 100.0, first + 100)
    params, _ = fit_correlations(corr, first, 100.0, vehicle, cfg)
    assert np.all(np.abs(params / TRUTH - 1) < 1e-4)


def test_sensors_off_the_axles_are_handled():
    v = Vehicle(sensor_front_offset_m=0.4, sensor_rear_offset_m=-0.5)
    est = estimate(free_decay(v), 100.0, v, METHODS["rozyn-condensed"].replace(**FREE_DECAY))
    assert np.all(np.abs(est.params / TRUTH - 1) < 1e-3)


def test_random_road_estimate_with_covariance(vehicle):
    sim = Simulation(SimConfig(duration_s=100.0, seed=2))
    block = sim.run(100.0)
    est = estimate(block.accel_mps2, 100.0, vehicle, METHODS["rozyn"], speed_mps=sim.config.speed_mps)
    assert est.ok, est.reason
    assert np.all(np.abs(est.params / TRUTH - 1) < 0.06)
    assert est.covariance.shape == (3, 3)
    assert np.allclose(est.covariance, est.covariance.T)
    assert np.all(np.linalg.eigvalsh(est.covariance) >= -1e-9 * np.trace(est.covariance))
    assert est.a0.shape == (4, 4)
    record = json.loads(json.dumps(est.to_dict()))
    assert record["status"] == "ok" and len(record["modes"]) == 2


def _accel(n=10_000):
    return Simulation(SimConfig(duration_s=n / 100, seed=1)).run(n / 100).accel_mps2


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (lambda a: np.where(np.arange(len(a))[:, None] == 500, np.nan, a), "NaN or Inf"),
        (lambda a: np.where(np.arange(len(a))[:, None] == 7, np.inf, a), "NaN or Inf"),
        (lambda a: np.column_stack([a[:, 0], np.full(len(a), 9.81)]), "rear channel is constant"),
        (lambda a: a[:300], "window too short"),
        (lambda a: a[:, 0], "shape"),
        (lambda a: a.astype(complex), "real numbers"),
        (lambda a: np.array([["x", "y"]] * 10), "real numbers"),
    ],
)
def test_bad_input_fails_with_a_reason(vehicle, make, words):
    est = estimate(make(_accel()), 100.0, vehicle)
    assert est.status == "failed" and words in est.reason
    assert est.params is None and est.covariance is None


@pytest.mark.parametrize("fs", [0.0, -5.0, float("nan"), "100"])
def test_bad_rate_fails(vehicle, fs):
    est = estimate(_accel(), fs, vehicle)
    assert est.status == "failed" and "sample rate" in est.reason


def test_white_noise_finds_no_body_modes(vehicle):
    noise = np.random.default_rng(0).standard_normal((10_000, 2))
    est = estimate(noise, 100.0, vehicle, PipelineConfig(variance="none"))
    assert est.status == "failed"
    assert "body modes" in est.reason or "physical range" in est.reason


@pytest.mark.parametrize(
    ("changes", "field"),
    [({"gamma": 0}, "gamma"), ({"freq_band_hz": (3.0, 1.0)}, "freq_band_hz"),
     ({"stiffness_model": "eq9"}, "stiffness_model"), ({"max_lag_s": -1.0}, "max_lag_s"),
     ({"jackknife_blocks": 2}, "jackknife_blocks")],
)
def test_invalid_pipeline_config(changes, field):
    with pytest.raises(ConfigError, match=field):
        PipelineConfig(**changes)


def test_corner_impedance_static_limit(vehicle):
    for model in ("eq2-21", "eq2-22", "condensed"):
        zf, _ = corner_impedances(vehicle, 1e-9, model)
        assert zf.real == pytest.approx(45000 * 200000 / 245000, rel=1e-6)


def test_the_jackknife_runs_only_when_the_fallback_needs_it(vehicle):
    """Rozyn's jackknife std is published only when the refinement fails: a refined update
    skips it; the fallback runs it."""
    live = Simulation(SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=4, noise_std_mps2=0.05))
    window = live.run(120.0).accel_mps2
    est = estimate(window, 100.0, vehicle, PipelineConfig(), 100 / 3.6)
    assert est.stage == "likelihood" and est.rozyn.ok and est.rozyn.covariance is None
    assert np.all(np.abs(est.params / est.rozyn.params - 1) < 0.25)
    failing = PipelineConfig(likelihood=LikelihoodConfig(max_noise_share=1e-9))
    fallback = estimate(window, 100.0, vehicle, failing, 100 / 3.6)
    assert fallback.ok and fallback.stage == "rozyn" and fallback.covariance is not None
    assert any("likelihood refinement failed" in note for note in fallback.notes)
