"""The likelihood refinement: its half-car spectrum, gradient, fit, covariance and statuses."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PipelineConfig, estimate
from rozyn_estimator.method.likelihood import (
    HalfCarSpectrum,
    LikelihoodConfig,
    WhittleObjective,
    delay_characteristic,
    refine,
    window_spectra,
)
from rozyn_estimator.tolerances import Tolerances
from rozyn_estimator.vehicle import Vehicle
from sim_node.road import REFERENCE_CPM, RoadSpec, iso_gd_n0_m3
from sim_node.simulation import SimConfig, Simulation
from sim_node.vehicle_plant import state_space

from conftest import TRUTH

SPEED = 100 / 3.6


EXACT = Vehicle(tolerances=Tolerances.none())  # the fit in-model: every assumed value exactly known

def run(vehicle=None, seed=3, duration_s=100.0, noise=0.05, rate_hz=100.0, **sim):
    v = vehicle or Vehicle()
    cfg = SimConfig(vehicle=v, road=RoadSpec(amplitudes="gaussian"), seed=seed, duration_s=duration_s,
                    noise_std_mps2=noise, rate_hz=rate_hz, **sim)
    block = Simulation(cfg).run(duration_s)
    return block.accel_mps2, block.speed_mps


@pytest.fixture(scope="module")
def window():
    return run()


def road_velocity_psd(speed_mps: float) -> float:
    """Two-sided PSD of the ISO A road's velocity under a wheel at w = 2 [m^2/s^2/Hz]."""
    return 2.0 * math.pi**2 * iso_gd_n0_m3("A") * REFERENCE_CPM**2 * speed_mps


@pytest.mark.parametrize(("offsets", "heights"), [((0.0, 0.0), (0.0, 0.0)), ((0.4, -0.5), (0.55, 0.3))])
def test_spectrum_matches_the_plant_state_space(offsets, heights):
    """The condensed frequency-domain model equals the plant's 8-state model exactly (gravity
    through the geometry included)."""
    v = Vehicle(sensor_front_offset_m=offsets[0], sensor_rear_offset_m=offsets[1], cog_height_m=heights[0],
                wheel_centre_height_m=heights[1])
    f = np.linspace(0.3, 20.0, 300)
    model = HalfCarSpectrum(v, f, 100.0, SPEED, aliases=0)
    S, _ = model.spectrum(model.theta(TRUTH, 1.0, np.array([1e-30, 1e-30])), derivatives=False)
    ss = state_space(v)
    s = 2j * np.pi * f
    h = np.einsum("ij,fjk->fik", ss.c, np.linalg.solve(s[:, None, None] * np.eye(8) - ss.a, ss.b)) + ss.d
    # per unit road velocity at the front wheel, the rear's input delayed by L / v
    g = (h[:, :, 0] + h[:, :, 1] * np.exp(-s * v.wheelbase_m / SPEED)[:, None]) / s[:, None]
    expected = g[:, :, None] * g[:, None, :].conj()
    assert np.allclose(S, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize(
    ("spectra", "waviness", "suspension", "varying", "taper"),
    [("cross", False, False, False, 0.0), ("cross", True, True, True, 0.2),
     ("auto", True, False, False, 0.5)],
)
def test_gradient_matches_finite_differences(window, spectra, waviness, suspension, varying, taper):
    accel, _ = window
    sp = window_spectra(accel, 100.0, (0.5, 15.0), taper)
    speed = SPEED * (1 + 0.1 * np.sin(np.arange(accel.shape[0]) / 900.0)) if varying else SPEED
    model = HalfCarSpectrum(Vehicle(), sp.freq_hz, 100.0, speed, estimate_waviness=waviness,
                            estimate_suspension=suspension, road_shape_terms=3 if waviness else 0,
                            estimate_incoherence=waviness, window_weights=sp.window_weights)
    obj = WhittleObjective(model, sp, spectra)
    theta = model.theta(np.array([1030.0, 1900.0, 1.25]), 2e-3, np.array([3e-5, 5e-5]), waviness=2.2)
    theta[model.shape_slice] = [0.1, -0.05, 0.02][: model.shape_basis.shape[0]]
    if suspension:
        theta[-4:] = [0.05, -0.03, 0.1, -0.1]
    _, grad = obj.evaluate(theta)
    step = 1e-6
    numeric = np.array([(obj.fun(theta + step * e) - obj.fun(theta - step * e)) / (2 * step)
                        for e in np.eye(theta.size)])
    assert np.allclose(grad, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())
    fisher = obj.hess(theta)
    assert np.allclose(fisher, fisher.T) and np.linalg.eigvalsh(fisher).min() > 0


@pytest.mark.parametrize("taper", [0.0, 0.2])
def test_model_matches_the_simulated_spectrum_with_aliasing(taper):
    """Averaged periodograms of noise-free runs at 50 Hz equal the model's absolute level
    (road intensity from ISO 8608) across the band, aliasing included, tapered or not."""
    fs = 50.0
    runs = [run(seed=s, duration_s=60.0, noise=0.0, rate_hz=fs)[0] for s in range(8)]
    spectra = [window_spectra(a, fs, (0.5, 15.0), taper) for a in runs]
    assert (spectra[0].window_dft.size == 1) == (taper == 0.0)
    mean = np.mean([sp.periodogram for sp in spectra], axis=0)
    f = spectra[0].freq_hz
    model = HalfCarSpectrum(Vehicle(), f, fs, SPEED, aliases=1, window_weights=spectra[0].window_weights)
    S, _ = model.spectrum(model.theta(TRUTH, road_velocity_psd(SPEED), np.array([1e-30, 1e-30])),
                          derivatives=False)
    bands = np.array_split(np.arange(f.size), 29)  # 0.5 Hz bands, 8 runs x 30 bins each
    for ch in (0, 1):
        ratio = np.array([mean[b, ch, ch].real.sum() / S[b, ch, ch].real.sum() for b in bands])
        assert np.all(np.abs(ratio - 1) < 0.25), ratio
        assert abs(np.mean(ratio) - 1) < 0.05


def test_window_cut_from_an_endless_run():
    """Not periodic: the taper keeps the front/rear coherence the fit relies on."""
    cfg = SimConfig(road=RoadSpec(amplitudes="gaussian"), seed=8, noise_std_mps2=0.05)
    accel = Simulation(cfg).run(150.0).accel_mps2[3000:]
    ref = refine(accel, 100.0, EXACT, np.array([950.0, 2100.0, 1.25]), SPEED)
    assert ref.ok
    assert np.all(np.abs(ref.params - TRUTH) < 4 * np.sqrt(np.diag(ref.covariance)))


@pytest.mark.parametrize(("spectra", "taper"), [("cross", 0.0), ("auto", 0.0), ("cross", 1.0)])
def test_score_covariance(window, spectra, taper):
    """Untapered and cross-spectral: the Fisher information. Auto-spectra: the channels'
    correlation adds Cov(I_ff, I_rr) = |S_fr|². Hann taper: neighbouring ordinates are
    correlated, about doubling the variance (Dahlhaus' factor 1.94)."""
    accel, _ = window
    sp = window_spectra(accel, 100.0, (0.5, 15.0), taper)
    model = HalfCarSpectrum(Vehicle(), sp.freq_hz, 100.0, SPEED, window_weights=sp.window_weights)
    obj = WhittleObjective(model, sp, spectra)
    theta = model.theta(TRUTH, 2e-3, np.array([3e-5, 5e-5]))
    combos = np.random.default_rng(1).standard_normal((3, theta.size))
    J = obj.score_covariance(theta, combos)
    F = combos @ obj.fisher(theta) @ combos.T
    if spectra == "auto":
        S, dS = model.spectrum(theta)
        u = np.einsum("pkaa->pka", np.tensordot(combos, dS, axes=1)).real / np.einsum("kaa->ka", S).real ** 2
        expected = np.einsum("pka,qkb,kab->pq", u, u, np.abs(S) ** 2)
        # the sum over frequency by the midpoint rule (0.1 Hz): 1e-3 of it in any direction
        assert np.allclose(J, expected, rtol=1e-3, atol=1e-3 * np.diag(expected).max())
    elif taper == 0.0:
        assert np.allclose(J, F, rtol=1e-3, atol=1e-3 * np.diag(F).max())
    else:
        assert np.all((np.diag(J) / np.diag(F) > 1.4) & (np.diag(J) / np.diag(F) < 2.1))


def _brute_force_score_covariance(obj, model, theta, combos):
    """Σ_(k,k') Re tr(A_ik C_kk' A_jk' C_k'k) over every pair of bins, C from its definition."""
    S_ext = model.variant(grid_step=1).spectrum(theta, derivatives=False, smooth=False)[0]
    S, dS = obj.model_at(theta)
    inv = np.linalg.inv(S)
    A = inv[None] @ np.tensordot(combos, dS, axes=1) @ inv[None]
    w = obj.window_dft
    J, k = model.half, model.n_freq
    w_hat = w[(w.size - 1) // 2 - J: (w.size - 1) // 2 + J + 1]
    out = np.zeros((combos.shape[0],) * 2)
    for d in range(-2 * J, 2 * J + 1):
        js = [j for j in range(-J, J + 1) if -J <= j + d <= J]
        C = sum(w_hat[j + J] * np.conj(w_hat[j + d + J]) * S_ext[J - j: J - j + k] for j in js)
        lo, hi = max(0, -d), min(k, k - d)
        X = A[:, lo:hi] @ C[None, lo:hi]
        Y = A[:, lo + d: hi + d] @ C[None, lo:hi].conj().transpose(0, 1, 3, 2)
        out += np.einsum("ikab,jkba->ij", X, Y).real
    return out


@pytest.mark.parametrize(("duration_s", "grid_step", "rtol"),
                         [(10.0, 1, 1e-9), (20.0, 1, 1e-3), (120.0, 6, 2e-3)])
def test_score_covariance_equals_the_double_sum_over_bins(duration_s, grid_step, rtol):
    """The fast score covariance (the midpoint rule over 0.1 Hz: exact for a 10 s window)
    equals the double sum over every pair of bins with C from its definition."""
    accel, _ = run(duration_s=duration_s)
    sp = window_spectra(accel, 100.0, (0.5, 15.0), 0.2)
    model = HalfCarSpectrum(Vehicle(), sp.freq_hz, 100.0, SPEED, window_weights=sp.window_weights,
                            estimate_waviness=True, road_shape_terms=2, grid_step=grid_step)
    obj = WhittleObjective(model, sp)
    theta = model.theta(TRUTH, 2e-3, np.array([3e-5, 5e-5]))
    combos = np.random.default_rng(2).standard_normal((3, theta.size))
    fast = obj.score_covariance(theta, combos)
    exact = _brute_force_score_covariance(obj, model, theta, combos)
    assert np.allclose(fast, exact, rtol=rtol, atol=rtol * np.abs(np.diag(exact)).max())


@pytest.mark.parametrize("speed_kmh", [10.0, 100.0])
def test_model_on_a_coarse_grid_equals_the_model_at_every_bin(speed_kmh):
    """Evaluated every 6th bin of a 120 s window (0.05 Hz) and interpolated, the tapered model
    and its derivatives equal the model evaluated at every bin (to 1e-4 of S), also at a low
    speed (the cross-spectrum's phase turning once per 0.36 Hz); so does S without the taper's
    smoothing at every bin of the extended grid (``fine_spectrum``)."""
    f = np.arange(60, 1801) / 120.0
    weights = window_spectra(np.random.default_rng(0).standard_normal((12000, 2)), 100.0, (0.5, 15.0),
                             0.2).window_weights
    args = dict(estimate_waviness=True, road_shape_terms=2, window_weights=weights, estimate_suspension=True)
    exact = HalfCarSpectrum(Vehicle(), f, 100.0, speed_kmh / 3.6, **args)
    coarse = HalfCarSpectrum(Vehicle(), f, 100.0, speed_kmh / 3.6, grid_step=6, **args)
    theta = exact.theta(TRUTH, 2e-3, np.array([3e-5, 5e-5]))
    (S0, dS0), (S1, dS1) = exact.spectrum(theta), coarse.spectrum(theta)
    scale = np.abs(S0).max(axis=(1, 2))[:, None, None]
    assert np.max(np.abs(S1 - S0) / scale) < 1e-4
    assert np.max(np.abs(dS1 - dS0) / scale[None]) < 1e-3 * np.max(np.abs(dS0) / scale[None])
    # unsmoothed at every bin of the extended grid (the score covariance's): interpolated only
    fine0, fine1 = exact.fine_spectrum(theta), coarse.fine_spectrum(theta)
    assert fine0.shape == fine1.shape == (exact.n_ext, 2, 2)
    assert np.max(np.abs(fine1 - fine0) / np.abs(fine0).max(axis=(1, 2))[:, None, None]) < 1e-4


def test_refinement_on_the_coarse_grid_matches_every_bin(window):
    """The default grid (0.05 Hz) moves the refined estimate by < 1 % of its std and its
    std by < 0.5 % against the model at every bin."""
    accel, speed = window
    every_bin = refine(accel, 100.0, EXACT, TRUTH, speed, LikelihoodConfig(grid_hz=0.0))
    coarse = refine(accel, 100.0, EXACT, TRUTH, speed)
    assert every_bin.ok and coarse.ok
    std = np.sqrt(np.diag(every_bin.covariance))
    assert np.all(np.abs(coarse.params - every_bin.params) < 0.01 * std)
    assert np.allclose(np.sqrt(np.diag(coarse.covariance)), std, rtol=5e-3)


def test_delay_characteristic():
    w = np.linspace(1.0, 100.0, 50)
    assert np.allclose(delay_characteristic(w, 2.8, 10.0), np.exp(-1j * w * 0.28))
    varying = delay_characteristic(w, 2.8, 10.0 * (1 + 0.1 * np.sin(np.linspace(0, 20, 5000))))
    assert np.all(np.abs(varying) <= 1 + 1e-12)
    assert abs(varying[-1]) < 0.9  # the delay spread smears the phase at high frequency
    assert abs(varying[0] - np.exp(-1j * 0.28)) < 0.01


def test_refine_recovers_the_truth_from_a_poor_start(window):
    accel, speed = window
    ref = refine(accel, 100.0, EXACT, np.array([800.0, 2600.0, 1.5]), speed)
    assert ref.ok, ref.reason
    assert np.all(np.abs(ref.params / TRUTH - 1) < 0.01)
    std = np.sqrt(np.diag(ref.covariance))
    assert np.all(std / TRUTH < 0.005) and np.all(std > 0)
    assert np.all(np.abs(ref.params - TRUTH) < 5 * std)
    assert 0.03 < ref.noise_std_mps2[0] < 0.07 and 0.03 < ref.noise_std_mps2[1] < 0.07  # 0.05 simulated
    assert abs(ref.waviness - 2.0) < 0.1
    json.dumps(ref.to_dict())


@pytest.mark.parametrize("start", [None, np.array([1000.0, 2000.0, 3.5])])
def test_without_a_usable_start_a_coarse_grid_starts_the_fit(window, start):
    accel, speed = window
    ref = refine(accel, 100.0, EXACT, start, speed)
    assert ref.ok and np.all(np.abs(ref.params / TRUTH - 1) < 0.01)


def test_white_noise_is_refused_as_noise():
    noise = np.random.default_rng(0).standard_normal((10_000, 2))
    ref = refine(noise, 100.0, EXACT, TRUTH, SPEED)
    assert ref.status == "failed" and "noise" in ref.reason


def test_warm_start_converges_faster_to_the_same_optimum(window):
    accel, speed = window
    cold = refine(accel, 100.0, EXACT, np.array([950.0, 2100.0, 1.25]), speed)
    warm = refine(accel, 100.0, EXACT, np.array([950.0, 2100.0, 1.25]), speed, warm=cold)
    assert cold.ok and warm.ok
    assert np.allclose(warm.params, cold.params, rtol=1e-4)
    assert warm.iterations < cold.iterations


def test_auto_spectra_only_are_much_less_precise(window):
    accel, speed = window
    cross = refine(accel, 100.0, EXACT, np.array([1000.0, 2000.0, 1.2]), speed)
    auto = refine(accel, 100.0, EXACT, np.array([1000.0, 2000.0, 1.2]), speed,
                  METHODS["likelihood-auto"].likelihood)
    assert auto.ok, auto.reason
    assert np.all(np.diag(auto.covariance) > 4 * np.diag(cross.covariance))


def test_nuisance_suspension_removes_a_stiffness_error(window):
    accel, speed = window
    # +10 %
    told = EXACT.replace(suspension_stiffness_front_npm=49_500.0, suspension_stiffness_rear_npm=88_000.0)
    start = np.array([1000.0, 2000.0, 1.2])
    fixed = refine(accel, 100.0, told, start, speed)
    free = refine(accel, 100.0, told, start, speed, LikelihoodConfig(estimate_suspension=True))
    assert fixed.ok and free.ok
    assert fixed.params[0] / 1000 - 1 > 0.03  # a 10 % stiffness error costs several % in mass
    std = np.sqrt(np.diag(free.covariance))
    assert np.all(np.abs(free.params - TRUTH) < 4 * std) and abs(free.params[0] / 1000 - 1) < 0.02
    assert abs(free.suspension_scale[0] - 1 / 1.1) < 0.03 and abs(free.suspension_scale[1] - 1 / 1.1) < 0.03


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (dict(speed=-1.0), "positive speed"),
        (dict(speed=np.full(7, SPEED)), "speed: expected"),
        (dict(config=LikelihoodConfig(band_hz=(0.5, 0.8))), "too few frequencies"),
    ],
)
def test_refine_failures_are_statuses(window, args, words):
    accel, _ = window
    start, speed = args.get("start", TRUTH), args.get("speed", SPEED)
    ref = refine(accel, 100.0, EXACT, start, speed, args.get("config"))
    assert ref.status == "failed" and words in ref.reason and ref.params is None


@pytest.mark.parametrize(("changes", "field"), [({"band_hz": (2.0, 1.0)}, "band_hz"),
                                                 ({"spectra": "both"}, "spectra"),
                                                 ({"aliases": -1}, "aliases"),
                                                 ({"block_s": 0.0}, "block_s"),
                                                 ({"block_weight": 1.5}, "block_weight")])
def test_invalid_likelihood_config(changes, field):
    with pytest.raises(ConfigError, match=field):
        LikelihoodConfig(**changes)


def test_pipeline_refines_and_keeps_rozyns_estimate(window):
    accel, speed = window
    est = estimate(accel, 100.0, EXACT, PipelineConfig(), speed_mps=speed)
    assert est.ok and est.stage == "likelihood" and not est.notes
    rozyn = estimate(accel, 100.0, EXACT, METHODS["rozyn"], speed_mps=speed)
    assert np.allclose(est.rozyn.params, rozyn.params) and est.rozyn_stage is est.rozyn
    assert rozyn.rozyn_stage is rozyn and rozyn.stage == "rozyn"
    assert np.all(np.abs(est.params / TRUTH - 1) < 0.01)
    assert len(est.modes) == 2
    record = json.loads(json.dumps(est.to_dict()))
    assert record["stage"] == "likelihood" and record["rozyn"]["mass_kg"] == pytest.approx(rozyn.params[0])
    assert record["refinement"]["status"] == "ok"


def test_pipeline_falls_back_to_rozyn_with_a_warning(window):
    accel, _ = window
    est = estimate(accel, 100.0, EXACT, PipelineConfig())  # no speed: no wheelbase delay
    assert est.ok and est.stage == "rozyn"
    assert np.allclose(est.params, est.rozyn.params)
    assert "publishing the Rozyn estimate" in est.notes[0] and "speed" in est.notes[0]


@pytest.mark.parametrize("warm", [True, False])
def test_the_refinement_stands_in_for_a_failed_rozyn_stage(window, warm):
    accel, speed = window
    previous = estimate(accel, 100.0, EXACT, PipelineConfig(), speed_mps=speed)
    # Rozyn's stage finds no body modes in a band where there are none.
    strict = PipelineConfig(freq_band_hz=(5.0, 6.0))
    est = estimate(accel, 100.0, EXACT, strict, speed_mps=speed, warm_start=previous if warm else None)
    assert est.ok and est.stage == "likelihood" and est.rozyn.status == "failed"
    assert "Rozyn stage failed" in est.notes[0]
    assert ("previous estimate" if warm else "coarse grid") in est.notes[0]
    assert np.allclose(est.params, previous.params, rtol=1e-4)


def test_no_estimate_when_both_stages_fail():
    noise = np.random.default_rng(1).standard_normal((10_000, 2))
    est = estimate(noise, 100.0, EXACT, PipelineConfig(variance="none"), speed_mps=SPEED)
    assert est.status == "failed" and est.params is None
    assert "likelihood refinement failed" in est.reason


def test_free_decay_has_nothing_to_refine():
    with pytest.raises(ConfigError, match="refine"):
        PipelineConfig(correlation="free-decay")


def test_score_series_sums_to_the_score(window):
    """The time-block variance rests on Parseval: ψ(t) summed over the samples is the
    score's data term Σ_k tr(A_k I_k), tapered or not, and ψ is local (a block's sum is
    far below the sum of its |ψ|)."""
    from rozyn_estimator.method.likelihood.covariance import _score_series

    accel, _ = window
    for taper in (0.0, 0.2):
        sp = window_spectra(accel, 100.0, (0.5, 15.0), taper)
        model = HalfCarSpectrum(Vehicle(), sp.freq_hz, 100.0, SPEED, estimate_waviness=True,
                                road_shape_terms=2, window_weights=sp.window_weights)
        obj = WhittleObjective(model, sp)
        theta = model.theta(TRUTH, 2e-3, np.array([3e-5, 5e-5]), waviness=2.1)
        combos = np.random.default_rng(2).standard_normal((3, theta.size))
        psi = _score_series(obj, theta, combos)
        S, dS = model.spectrum(theta)
        inv = np.linalg.inv(S)
        A = inv[None] @ np.tensordot(combos, dS, axes=1) @ inv[None]
        expected = np.einsum("qkab,kba->q", A, sp.periodogram).real
        assert psi.shape == (3, accel.shape[0])
        assert np.allclose(psi.sum(axis=1), expected, rtol=1e-9)


def _laplace_run(seed, nu):
    cfg = SimConfig(road=RoadSpec(kind="laplace", laplace_nu=nu, amplitudes="gaussian"), seed=seed,
                    duration_s=100.0, noise_std_mps2=0.05)
    block = Simulation(cfg).run(100.0)
    return block.accel_mps2, block.speed_mps


def test_time_blocks_widen_the_covariance_on_a_non_stationary_road():
    """The model's J assumes a stationary road. On Laplace roads (ν = 1: the intensity
    jumps every 100 m) l_f's estimate varies ~1.4x the model's variance; the blocks
    measure that, so the published l_f variance grows there, and stays the model's on
    average on Gaussian roads (both within their sampling noise over 32 runs: a run's l_f factor
    spreads by about 0.4, so 8 runs' means were 0.14 apart by chance)."""
    start = np.array([950.0, 2100.0, 1.25])
    factors = {}
    for nu in (0.0, 1.0):
        f = []
        for seed in range(32):
            accel, speed = _laplace_run(seed, nu)
            ref = refine(accel, 100.0, EXACT, start, speed)
            assert ref.ok, ref.reason
            assert len(ref.variance_factors) == 3
            f.append(ref.variance_factors)
        factors[nu] = np.mean(f, axis=0)
    assert 0.8 < factors[0.0][2] < 1.2 and np.all((factors[0.0] > 0.75) & (factors[0.0] < 1.3)), factors
    assert factors[1.0][2] > 1.1 and factors[1.0][2] > factors[0.0][2] + 0.1, factors


def test_block_weight_zero_is_the_model_sandwich(window):
    """block_weight = 0 publishes the model sandwich; a window too short for 6 blocks of
    block_s keeps it too; otherwise the factors scale the variances, correlations kept."""
    accel, speed = window
    start = np.array([950.0, 2100.0, 1.25])
    model_only = refine(accel, 100.0, EXACT, start, speed, LikelihoodConfig(block_weight=0.0))
    blended = refine(accel, 100.0, EXACT, start, speed)
    few = refine(accel, 100.0, EXACT, start, speed, LikelihoodConfig(block_s=20.0))
    assert model_only.ok and blended.ok and few.ok
    assert model_only.variance_factors == (1.0, 1.0, 1.0) and few.variance_factors == (1.0, 1.0, 1.0)
    assert np.allclose(few.covariance, model_only.covariance)
    f = np.array(blended.variance_factors)
    assert np.all(f > 0.5) and not np.allclose(f, 1.0)
    assert np.allclose(np.diag(blended.covariance), f * np.diag(model_only.covariance))

    def corr(c):
        s = np.sqrt(np.diag(c))
        return c / np.outer(s, s)

    assert np.allclose(corr(blended.covariance), corr(model_only.covariance))


def test_every_derivative_of_the_model_matches_finite_differences():
    """dS/dθ of the half-car spectrum with every optional nuisance (corner values, sensor
    positions, the rear sensor's gain and delay) against central differences of S."""
    from rozyn_estimator.method.likelihood.model import CORNER_TERMS

    freq = np.linspace(0.5, 15.0, 300)
    vehicle = Vehicle(sensor_front_offset_m=0.2, cog_height_m=0.55, wheel_centre_height_m=0.3)  # gravity too
    model = HalfCarSpectrum(vehicle, freq, 100.0, np.full(500, 25.0) +
                            np.linspace(0, 2, 500), aliases=1, estimate_waviness=True, road_shape_terms=2,
                            window_weights=np.array([0.25, 0.5, 0.25]), corner_terms=CORNER_TERMS,
                            sensor_positions=True, calibrate_gain=True, calibrate_time_offset=True)
    rng = np.random.default_rng(3)
    theta = model.theta(np.array([1000.0, 2000.0, 1.2]), 1e-4, np.array([1e-6, 2e-6]))
    theta[6:] += 0.05 * rng.standard_normal(theta.size - 6)
    _, dS = model.spectrum(theta)
    for j, name in enumerate(model.names):
        h = 1e-6 * max(1.0, abs(theta[j]))
        hi, lo = theta.copy(), theta.copy()
        hi[j] += h
        lo[j] -= h
        fd = (model.spectrum(hi, derivatives=False)[0] - model.spectrum(lo, derivatives=False)[0]) / (2 * h)
        scale = np.max(np.abs(fd)) + 1e-30
        assert np.max(np.abs(dS[j] - fd)) < 1e-5 * scale, name
