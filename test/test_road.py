from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import welch
from scipy.stats import kurtosis

from rozyn_estimator.errors import ConfigError
from sim_node.road import Road, RoadSpec, iso_gd_n0_m3


def test_iso_classes():
    assert iso_gd_n0_m3("A") == pytest.approx(16e-6)
    assert iso_gd_n0_m3("h") == pytest.approx(262144e-6)
    with pytest.raises(ConfigError, match="road_class"):
        iso_gd_n0_m3("Z")


@pytest.mark.parametrize("amplitudes", ["fixed", "gaussian"])
def test_psd_follows_iso_8608(amplitudes):
    """Welch PSD of the grid heights within 10 % (fixed) / 20 % (gaussian) of Gd(n),
    averaged over octave bands between 0.05 and 4 cycles/m."""
    spec = RoadSpec(amplitudes=amplitudes, road_class="C")
    road = Road(spec, seed=4, period_m=20_000.0)
    s = np.arange(0, road.period_m, road.dx_m)
    f, p = welch(road.heights(s), fs=1 / road.dx_m, nperseg=8192)
    tol = 0.10 if amplitudes == "fixed" else 0.20
    for lo in 0.05 * 2.0 ** np.arange(6):
        band = (f >= lo) & (f < 2 * lo)
        assert np.mean(p[band] / spec.psd_m3(f[band])) == pytest.approx(1.0, rel=tol), lo


def test_variance_and_waviness():
    spec = RoadSpec(waviness=2.5, n_min_cpm=0.02, n_max_cpm=4.0)
    road = Road(spec, seed=1, period_m=5000.0)
    s = np.arange(0, road.period_m, road.dx_m)
    n = np.linspace(spec.n_min_cpm, spec.n_max_cpm, 200_001)
    expected = np.sum(spec.psd_m3(n)) * (n[1] - n[0])
    assert np.var(road.heights(s)) == pytest.approx(expected, rel=0.01)  # fixed: deterministic


@pytest.mark.parametrize("nu", [0.5, 1.0])
def test_laplace_kurtosis_is_3_nu(nu):
    """Excess kurtosis 3 nu within 25 % over 4000 sections (sampled once per 5 m)."""
    spec = RoadSpec(kind="laplace", laplace_nu=nu, dx_m=0.5, n_max_cpm=0.9)
    road = Road(spec, seed=11, period_m=20_000.0)
    h = road.heights(np.arange(0, 400_000.0, 5.0))
    assert kurtosis(h) == pytest.approx(3 * nu, rel=0.25)


def test_laplace_nu_zero_is_the_iso_road():
    s = np.linspace(0, 3000, 7001)
    iso = Road(RoadSpec(), 3, period_m=3000.0).heights(s)
    lap = Road(RoadSpec(kind="laplace", laplace_nu=0.0), 3, period_m=3000.0).heights(s)
    assert np.array_equal(iso, lap)


def test_laplace_envelope_has_no_steps():
    spec = RoadSpec(kind="laplace", laplace_nu=1.0)
    road = Road(spec, 5, period_m=10_000.0)
    s = np.arange(0, 10_000.0, 0.01)
    env = road.envelope(s)
    assert np.mean(env**2) == pytest.approx(1.0, rel=0.3)
    # the envelope moves at most by its jump over the ramp's raised cosine per step
    steps = np.abs(np.diff(env))
    assert steps.max() < np.pi / 2 * np.ptp(env) * 0.01 / spec.envelope_ramp_m
    # at section boundaries heights are continuous: same slope scale as inside sections
    h = road.heights(s)
    assert np.max(np.abs(np.diff(h))) < 5 * np.percentile(np.abs(np.diff(h)), 99.9)


def test_streaming_any_blocks_any_order():
    road = Road(RoadSpec(kind="laplace"), 9, period_m=2000.0)
    s = np.linspace(-50, 4500, 9000)
    whole = road.heights(s)
    parts = np.concatenate([road.heights(s[4000:]), road.heights(s[:4000])])
    assert np.array_equal(np.concatenate([parts[-4000:], parts[:-4000]]), whole)
    # periodic: one period later the base profile repeats
    iso = Road(RoadSpec(), 9, period_m=2000.0)
    assert np.allclose(iso.heights(s), iso.heights(s + iso.period_m), atol=1e-12)


def test_seeds_differ_and_repeat():
    s = np.linspace(0, 500, 1001)
    a = Road(RoadSpec(), 1, period_m=1000.0).heights(s)
    assert np.array_equal(a, Road(RoadSpec(), 1, period_m=1000.0).heights(s))
    assert not np.allclose(a, Road(RoadSpec(), 2, period_m=1000.0).heights(s))


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"kind": "gravel"}, "road.kind"),
        ({"amplitudes": "random"}, "road.amplitudes"),
        ({"dx_m": -1.0}, "road.dx_m"),
        ({"n_max_cpm": 20.0}, "road.n_max_cpm"),
        ({"laplace_nu": -0.1}, "road.laplace_nu"),
        ({"waviness": 0.0}, "road.waviness"),
    ],
)
def test_invalid_specs(changes, field):
    with pytest.raises(ConfigError, match=field):
        RoadSpec(**changes)
