"""Periodograms of a window: :class:`Spectra` (the front/rear periodogram matrices at the
Fourier frequencies of a band, with the taper's spectral window and the DFT) from
:func:`window_spectra`, and each channel's power in the band (:func:`band_power`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy import fft as sfft
from scipy.signal import windows


@dataclass(frozen=True)
class Spectra:
    """Periodogram matrices of a window at the Fourier frequencies of a band.

    ``periodogram[k] = d_k d_kᴴ / (n fs)`` with ``d_k`` the DFT of the demeaned, tapered
    (front, rear) accelerations (taper normalised to mean square 1): a two-sided PSD
    [(m/s²)²/Hz] whose expectation is the sampled signals' spectral matrix.
    ``window_dft`` ``ŵ_j`` (j = -J..J) is the taper's DFT at the Fourier frequencies (``[1]``
    untapered): the tapered DFT is ``d_k = Σ_j ŵ_j D_(k-j)``, ``D`` the untapered one, so
    (exactly for a periodic record, closely otherwise) the tapered periodogram's
    expectation is ``Σ_j |ŵ_j|² S(f_(k-j))`` and neighbouring ordinates are correlated.
    """

    freq_hz: np.ndarray  # (k,)
    periodogram: np.ndarray  # (k, 2, 2) complex, Hermitian
    fs_hz: float
    n_samples: int
    window_dft: np.ndarray = field(default_factory=lambda: np.ones(1, dtype=complex))
    dft: np.ndarray | None = None  # (k, 2) the tapered DFT d_k at the band's frequencies
    first_bin: int = 0  # index of the band's first frequency among the window's n // 2 + 1

    @property
    def window_weights(self) -> np.ndarray:
        """The taper's spectral window ``|ŵ_j|²`` (sums to 1)."""
        c = np.abs(self.window_dft) ** 2
        return c / c.sum()


def window_spectra(
    accel_mps2: np.ndarray, fs_hz: float, band_hz: tuple[float, float], taper: float = 0.0
) -> Spectra:
    """Periodogram matrices of ``(n, 2)`` accelerations at the Fourier frequencies in ``band_hz``.

    ``taper`` is the share of the window under a cosine taper (Tukey window, 0: none). A
    window cut from a longer record is not periodic: its DFT carries the response's
    transients at the window's ends, which break the front/rear coherence the fit relies
    on; the taper fades them out.
    """
    y = np.asarray(accel_mps2, dtype=float)
    y = y - y.mean(axis=0)
    n = y.shape[0]
    w, window_dft = _taper(n, float(taper))
    freq = np.arange(n // 2 + 1) * (fs_hz / n)
    keep = (freq >= band_hz[0]) & (freq <= band_hz[1])
    d = sfft.rfft(y * w[:, None], axis=0)[keep]
    per = d[:, :, None] * d[:, None, :].conj() / (n * fs_hz)
    return Spectra(freq_hz=freq[keep], periodogram=per, fs_hz=float(fs_hz), n_samples=n,
                   window_dft=window_dft, dft=d, first_bin=int(np.argmax(keep)))


@lru_cache(maxsize=8)
def _taper(n: int, taper: float) -> tuple[np.ndarray, np.ndarray]:
    """(the taper of an ``n``-sample window normalised to mean square 1, its DFT ``ŵ_j`` at the
    Fourier frequencies it reaches, j = -J..J): cached, consecutive windows share them."""
    w = windows.tukey(n, taper) if taper > 0 else np.ones(n)
    w = w / np.sqrt(np.mean(w * w))
    w_hat = sfft.fft(w) / n  # Σ |ŵ|² = mean(w²) = 1 (Parseval)
    c = np.abs(w_hat) ** 2
    half = int(np.argmax(np.cumsum(c[: n // 2] + np.r_[0.0, c[:0:-1][: n // 2 - 1]]) >= 1.0 - 1e-4))
    window_dft = np.r_[w_hat[n - half:] if half else np.zeros(0, dtype=complex), w_hat[: half + 1]]
    for a in (w, window_dft):
        a.flags.writeable = False  # shared by the cache
    return w, window_dft


def taper_window(n: int, taper: float) -> np.ndarray:
    """The taper :func:`window_spectra` applies to an ``n``-sample window (mean square 1)."""
    return _taper(n, float(taper))[0]


def band_power(spectra: Spectra) -> np.ndarray:
    """Mean PSD of each channel over the band [(m/s²)²/Hz]."""
    return np.einsum("kaa->a", spectra.periodogram).real / spectra.freq_hz.size
