from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import coherence, csd, welch

from sim_node.road import Road, RoadSpec
from sim_node.tracks import RoadTracks, isotropic_coherence

BANDS = 0.02 * 2.0 ** np.arange(6)  # octave bands from 0.02 to 1.28 cycles/m


def _grid(tracks: RoadTracks) -> np.ndarray:
    return tracks.heights(np.arange(0, tracks.period_m, tracks.left.dx_m))


@pytest.mark.parametrize("amplitudes", ["fixed", "gaussian"])
def test_each_track_follows_iso_8608_and_the_coherence_the_model(amplitudes):
    """Each track's Welch PSD within 10 % (fixed) / 20 % (gaussian) of Gd(n) per octave band, and
    the estimated coherence |S_LR| / sqrt(S_LL S_RR) within 0.05 of the isotropic model's mean in
    each band (600 averages per estimate: the estimator's own bias and scatter are about 0.02)."""
    spec = RoadSpec(amplitudes=amplitudes, road_class="C", dx_m=0.1, n_min_cpm=0.005, n_max_cpm=4.0)
    tracks = RoadTracks(spec, seed=4, separation_m=1.5, period_m=120_000.0)
    h = _grid(tracks)
    fs = 1 / tracks.left.dx_m
    tol = 0.10 if amplitudes == "fixed" else 0.20
    f, c2 = coherence(h[:, 0], h[:, 1], fs=fs, nperseg=2048)
    for side in (0, 1):
        f, p = welch(h[:, side], fs=fs, nperseg=2048)
        for lo in BANDS:
            band = (f >= lo) & (f < 2 * lo)
            assert np.mean(p[band] / spec.psd_m3(f[band])) == pytest.approx(1.0, rel=tol), (side, lo)
    for lo in BANDS[1:]:
        band = (f >= lo) & (f < 2 * lo)
        model = np.mean(tracks.coherence(f[band]))
        assert np.mean(np.sqrt(c2[band])) == pytest.approx(model, abs=0.05), lo
    # the model falls with spatial frequency
    assert tracks.coherence(np.array([0.01])) > 0.9 > 0.5 > tracks.coherence(np.array([0.3]))


def test_the_cross_spectrum_is_real_no_lateral_shift():
    """An isotropic road has no preferred side: the left-right cross-spectrum is real (in phase)."""
    spec = RoadSpec(amplitudes="gaussian", dx_m=0.1, n_max_cpm=4.0)
    tracks = RoadTracks(spec, seed=2, separation_m=1.5, period_m=60_000.0)
    h = _grid(tracks)
    f, s = csd(h[:, 0], h[:, 1], fs=1 / tracks.left.dx_m, nperseg=2048)
    band = (f > 0.02) & (f < 0.2)
    assert np.mean(np.abs(s[band].imag)) < 0.1 * np.mean(np.abs(s[band].real))


def test_isotropic_coherence_closed_form_for_waviness_2():
    from scipy.special import k1

    n = np.array([0.0, 0.01, 0.1, 0.5, 1e3])
    x = 2 * np.pi * n * 1.5
    expected = np.where(x > 0, x * k1(np.where(x > 0, x, 1.0)), 1.0)  # gamma = x K_1(x)
    assert np.allclose(isotropic_coherence(n, 1.5, 2.0), expected, atol=1e-15)
    assert isotropic_coherence(np.array([0.1]), 0.0, 2.0)[0] == 1.0  # one track
    wider = isotropic_coherence(np.array([0.1]), 2.0, 2.0)[0]
    assert wider < isotropic_coherence(np.array([0.1]), 1.5, 2.0)[0]


@pytest.mark.parametrize("amplitudes", ["fixed", "gaussian"])
def test_left_track_is_the_half_cars_road_and_identical_tracks_are_equal(amplitudes):
    spec = RoadSpec(amplitudes=amplitudes)
    s = np.linspace(0, 3000, 9001)
    tracks = RoadTracks(spec, 7, 1.5, period_m=3000.0)
    assert np.array_equal(tracks.left.heights(s), Road(spec, 7, period_m=3000.0).heights(s))
    same = RoadTracks(spec, 7, 1.5, period_m=3000.0, coherence="identical").heights(s)
    assert np.array_equal(same[:, 0], same[:, 1])
    assert not np.allclose(tracks.heights(s)[:, 1], tracks.heights(s)[:, 0])


def test_laplace_tracks_share_the_roads_envelope():
    spec = RoadSpec(kind="laplace", laplace_nu=1.0)
    tracks = RoadTracks(spec, 3, 1.5, period_m=5000.0)
    s = np.linspace(0, 5000, 2001)
    assert np.array_equal(tracks.left.envelope(s), tracks.right.envelope(s))
    assert np.array_equal(tracks.left.heights(s), Road(spec, 3, period_m=5000.0).heights(s))


def test_deterministic_per_seed_and_streaming():
    spec = RoadSpec()
    s = np.random.default_rng(0).uniform(0, 10_000, 500)
    a = RoadTracks(spec, 11, 1.5, period_m=10_000.0)
    b = RoadTracks(spec, 11, 1.5, period_m=10_000.0)
    c = RoadTracks(spec, 12, 1.5, period_m=10_000.0)
    assert np.array_equal(a.heights(s), b.heights(s))
    assert not np.allclose(a.heights(s)[:, 1], c.heights(s)[:, 1])
    assert np.array_equal(a.heights(s)[::-1], a.heights(s[::-1]))  # any order
    assert a.heights(s.reshape(20, 25)).shape == (20, 25, 2)


def test_bad_arguments():
    with pytest.raises(ValueError, match="coherence"):
        RoadTracks(RoadSpec(), 1, 1.5, period_m=100.0, coherence="exponential")
    with pytest.raises(ValueError, match="separation_m"):
        RoadTracks(RoadSpec(), 1, -1.0, period_m=100.0)
    with pytest.raises(ValueError, match="coefficients"):
        Road(RoadSpec(), 1, period_m=100.0, coefficients=np.zeros(3))
