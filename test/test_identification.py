"""Modal identification from free decays (thesis sections 2-2, 2-3) on synthetic decays."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.method.identification import (
    IdentificationError,
    Mode,
    select_body_modes,
    state_transition_modes,
)

FS = 100.0
POLES = np.array([-0.6 + 2j * np.pi * 1.2, -1.1 + 2j * np.pi * 1.8, -30.0 + 2j * np.pi * 11.0])
SHAPES = np.array([[1.0, 0.8], [1.0, -0.7], [0.3, 1.0]])  # (front, rear) per mode


def decays(n_lags: int = 150, refs: int = 2, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """(1, refs, n_lags, 2) free decays: sums of the three damped modes, other excitations per ref."""
    t = np.arange(n_lags) / FS
    rng = np.random.default_rng(seed)
    out = np.zeros((1, refs, n_lags, 2))
    for r in range(refs):
        c = rng.normal(size=3) + 1j * rng.normal(size=3)
        wave = (c[:, None] * np.exp(POLES[:, None] * t)).real  # (modes, lags)
        out[0, r] = wave.T @ SHAPES + noise * rng.normal(size=(n_lags, 2))
    return out


def test_state_transition_recovers_poles_and_shapes():
    (modes,) = state_transition_modes(decays(), 1 / FS, p_blocks=4)
    for pole, shape in zip(POLES, SHAPES, strict=True):
        best = min(modes, key=lambda m: abs(m.eigenvalue - pole))
        assert best.eigenvalue == pytest.approx(pole, rel=1e-6)
        expected = shape / shape[np.argmax(np.abs(shape))]
        assert np.array(best.shape) == pytest.approx(expected, abs=1e-4)  # the ridge of eq 2-9
    assert sum(m.amplitude for m in modes) == pytest.approx(1.0)


def test_principal_branch_gives_frequency_and_damping():
    mode = Mode(complex(POLES[0]), (1.0, 0.8), 1.0)
    assert mode.freq_hz == pytest.approx(abs(POLES[0]) / (2 * np.pi))  # eq 2-17
    assert mode.damping_ratio == pytest.approx(0.6 / abs(POLES[0]))  # eq 2-19


def test_batch_items_are_identified_on_their_own():
    two = np.concatenate([decays(seed=1), decays(seed=2) * 3.0])
    out = state_transition_modes(two, 1 / FS, p_blocks=4)
    assert len(out) == 2
    for modes in out:
        assert min(abs(m.eigenvalue - POLES[1]) for m in modes) < 1e-6 * abs(POLES[1])


def test_too_short_a_decay_is_an_error():
    with pytest.raises(IdentificationError, match="too short"):
        state_transition_modes(decays(n_lags=5, refs=1), 1 / FS, p_blocks=4)


def test_body_modes_by_band_and_amplitude():
    modes = [Mode(complex(p), (1.0, 0.5), a) for p, a in zip(POLES, (0.3, 0.2, 0.5), strict=True)]
    noise_mode = Mode(-50.0 + 2j * np.pi * 2.0, (1.0, 1.0), 0.9)  # in the frequency band, damped ~0.97
    body = select_body_modes([*modes, noise_mode], (0.5, 4.0), (0.02, 0.9))
    assert [m.eigenvalue for m in body] == [modes[0].eigenvalue, modes[1].eigenvalue]


def test_body_modes_follow_the_reference_modes():
    modes = [Mode(complex(p), (1.0, 0.5), 0.3) for p in POLES[:2]]
    strong = Mode(-0.9 + 2j * np.pi * 1.5, (1.0, 0.0), 0.9)
    assert select_body_modes([*modes, strong], (0.5, 4.0), (0.02, 0.9))[1] is strong
    # a jackknife replicate follows the full record's modes, not the strongest
    assert select_body_modes([*modes, strong], (0.5, 4.0), (0.02, 0.9), near=modes) == modes


def test_too_few_body_modes_names_what_was_seen():
    modes = [Mode(complex(POLES[0]), (1.0, 0.5), 1.0)]
    with pytest.raises(IdentificationError, match=r"found 1 of 2 body modes .*1\.20 Hz"):
        select_body_modes(modes, (0.5, 4.0), (0.02, 0.9))
