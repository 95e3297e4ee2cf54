"""Road profiles: ISO 8608 (thesis section 4-1-1) and Bogsjö's Laplace road (4-1-2).

A road is a height ``h(s)`` [m] along the distance ``s`` [m]. It is generated once on
a uniform grid (spacing at most ``dx_m``) as a periodic sum of cosines by an inverse FFT
(eqs 4-1 to 4-7), and read at any distances by cubic (Catmull-Rom) interpolation — so it
streams: any block of positions can be asked for, in any order, and the answer does not
depend on how a run is cut into blocks. The true road of the sim is the piecewise-cubic
profile through the grid points.

Why cubic: a piecewise-linear profile adds images of the road's spectrum at multiples of
the grid's wavenumber (20 cycles/m), seen by the plant and aliased into the sensors' band;
they are not the road of the estimator's model, and with quiet sensors its model check
saw them (with the plant's 500 Hz steps, p < 0.001 in a quarter of noise-free in-model
runs). Catmull-Rom's images are smaller by the square of the grid's resolution of the
road, at the same memory (measured: in-model runs with the 1 kHz plant gave p < 0.05 in
7 % of 30 noise-free runs, 17 % with linear interpolation).

- ``amplitudes="fixed"``: amplitude ``sqrt(2 Gd(n_i) dn)`` and a uniform random phase
  per component (eq 4-6, the thesis' generator; nearly deterministic statistics).
- ``amplitudes="gaussian"``: complex Gaussian coefficients with the same mean square, a
  true (periodic) stationary Gaussian process.
- ``kind="laplace"``: the ISO profile times a smooth envelope ``sqrt(Y_k)`` per section
  of ``section_length_m``, ``Y_k ~ Gamma(shape 1/nu, scale nu)`` (mean 1, variance
  nu): a generalised Laplace marginal with excess kurtosis ``3 nu``. The envelope
  changes over ``envelope_ramp_m`` with a raised cosine, so the height has no steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy import fft as sfft

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.parameters import check, param

ROAD_KINDS = ("iso", "laplace", "flat")
AMPLITUDE_MODES = ("fixed", "gaussian")
ISO_CLASSES = "ABCDEFGH"
REFERENCE_CPM = 0.1  # n0 of ISO 8608 [cycles/m]
DEFAULT_PERIOD_M = 200_000.0  # road length before a run that never ends repeats
_CHUNK = 256  # Laplace sections drawn per random stream


def iso_gd_n0_m3(road_class: str) -> float:
    """Geometric-mean Gd(n0) of an ISO 8608 class: 16e-6 * 4**k m^3 (A..H)."""
    key = str(road_class).strip().upper()
    if len(key) != 1 or key not in ISO_CLASSES:
        raise ConfigError(f"road_class: must be one of A..H, got {road_class!r}")
    return 16e-6 * 4.0 ** ISO_CLASSES.index(key)


@dataclass(frozen=True)
class RoadSpec:
    """What road to generate (all lengths in metres, spatial frequencies in cycles/m).

    The described fields with a ROS name are ``sim_node``'s ``road.*`` parameters.
    """

    PARAM_PREFIX: ClassVar[str] = "road."

    kind: str = param("iso", "road model: iso (ISO 8608), laplace (Bogsjo) or flat (no excitation)",
                      choices=ROAD_KINDS, read_only=True)
    road_class: str = param("A", "ISO 8608 class A..H", ros_name="class", read_only=True)
    gd_n0_m3: float | None = None  # overrides road_class when set
    waviness: float = param(2.0, "ISO 8608 waviness w (eq 4-1)", low=0.5, high=5.0, read_only=True)
    amplitudes: str = param("fixed", "fixed (the thesis' generator) or gaussian (a true Gaussian road)",
                            choices=AMPLITUDE_MODES, read_only=True)
    n_min_cpm: float = param(0.01, "lowest spatial frequency (w = 2 diverges at 0)", unit="cycles/m",
                             low=0.0, open_low=True, ros_name="")
    n_max_cpm: float = param(5.0, "highest spatial frequency", unit="cycles/m", ros_name="")
    dx_m: float = param(0.025, "grid spacing at most", unit="m", low=0.0, open_low=True, ros_name="")
    laplace_nu: float = param(1.0, "Laplace road: variance of the section gamma variable (0: Gaussian)",
                              low=0.0, high=100.0, read_only=True)
    section_length_m: float = param(100.0, "Laplace road section length", unit="m", low=1.0, high=100_000.0,
                                    read_only=True)
    envelope_ramp_m: float = param(5.0, "Laplace road: length of the envelope's raised-cosine ramps",
                                   unit="m", low=0.0, ros_name="")

    def __post_init__(self) -> None:
        check(self, (
            ("road_class", lambda r: len(key := r.road_class.strip()) == 1 and key.upper() in ISO_CLASSES,
             "must be one of A..H"),
            ("n_max_cpm", lambda r: r.n_min_cpm < r.n_max_cpm < 0.5 / r.dx_m,
             "must exceed n_min_cpm and stay below the grid's Nyquist 0.5/dx_m"),
            ("envelope_ramp_m", lambda r: r.envelope_ramp_m <= r.section_length_m,
             "must lie in [0, section_length_m]"),
            ("gd_n0_m3", lambda r: r.gd_n0_m3 is None or r.gd_n0_m3 > 0, "must be > 0 m^3"),
        ))

    @property
    def roughness_m3(self) -> float:
        """Gd(n0) [m^3]."""
        return self.gd_n0_m3 if self.gd_n0_m3 is not None else iso_gd_n0_m3(self.road_class)

    def psd_m3(self, n_cpm: np.ndarray) -> np.ndarray:
        """One-sided displacement PSD Gd(n) [m^3] (eq 4-1), zero outside [n_min, n_max]."""
        n = np.asarray(n_cpm, dtype=float)
        inside = (n >= self.n_min_cpm) & (n <= self.n_max_cpm)
        with np.errstate(divide="ignore"):
            g = self.roughness_m3 * (np.where(inside, n, 1.0) / REFERENCE_CPM) ** (-self.waviness)
        return np.where(inside, g, 0.0) if self.kind != "flat" else np.zeros_like(n)


def road_grid(spec: RoadSpec, period_m: float | None) -> tuple[float, int]:
    """(period [m], grid points) of a road: ``period_m`` (None: DEFAULT_PERIOD_M) on a fast FFT
    length with spacing at most ``spec.dx_m``."""
    period = DEFAULT_PERIOD_M if period_m is None else float(period_m)
    if not period > 2.0 * spec.dx_m:
        raise ConfigError(f"road period must exceed two grid steps, got {period!r} m")
    return period, sfft.next_fast_len(int(np.ceil(period / spec.dx_m)), real=True)


def spectrum(spec: RoadSpec, period_m: float, n_grid: int) -> tuple[np.ndarray, float]:
    """(Gd [m^3] at the grid's spatial frequencies ``k dn``, k = 0 … n_grid // 2; ``dn = 1/period``
    [cycles/m])."""
    dn = 1.0 / period_m
    return spec.psd_m3(np.arange(n_grid // 2 + 1) * dn), dn


def iso_coefficients(spec: RoadSpec, gd: np.ndarray, dn: float, rng: np.random.Generator) -> np.ndarray:
    """Random Fourier coefficients ``c_k`` with mean square ``2 Gd dn`` (eq 4-6): a fixed amplitude
    and a uniform phase, or complex Gaussian (``spec.amplitudes``)."""
    if spec.amplitudes == "fixed":
        return np.sqrt(2.0 * gd * dn) * np.exp(2j * np.pi * rng.random(gd.size))
    return np.sqrt(gd * dn) * (rng.standard_normal(gd.size) + 1j * rng.standard_normal(gd.size))


def catmull_rom_response(nu: np.ndarray) -> np.ndarray:
    """The frequency response of Catmull-Rom interpolation (Keys' cubic convolution, a = -1/2)
    at ``nu`` cycles per grid step: a spectrum read between the grid points is this times the
    grid's (Park & Schowengerdt 1983). 1 at 0, 0.94 at a quarter cycle per step (5 cycles/m
    on a 0.05 m grid), 0.49 at the grid's Nyquist frequency."""
    nu = np.abs(np.asarray(nu, dtype=float))
    f = np.maximum(nu, 0.01)  # below, the closed form cancels: its series, 1 - pi^4 f^4 / 5 (to 1e-11)
    s = np.sinc
    a = -0.5
    pf2 = (np.pi * f) ** 2
    s1, s2, s4 = s(f), s(2 * f), s(4 * f)
    closed = (3.0 * (s1**2 - s2) + 2.0 * a * (3.0 * s2**2 - 2.0 * s2 - s4)) / pf2
    return np.where(nu < 0.01, 1.0 - np.pi**4 / 5.0 * nu**4, closed)


class Road:
    """A seeded road profile, read at any distances.

    Args:
        spec: the road model.
        seed: the random seed; equal seeds give equal roads.
        period_m: the profile repeats after this distance; ``None`` for
            ``DEFAULT_PERIOD_M``. A run of known length sets it to the distance its
            record covers: then ``dn = 1 / L`` as in eq 4-7, and the components are
            orthogonal over the record, as in the thesis.
        coefficients: the profile's complex Fourier coefficients ``c_k`` (the height is
            ``sum_k Re(c_k exp(2 pi i k s / period))``, ``k = 0 … n_grid // 2``) instead of
            drawn ones (:mod:`sim_node.tracks` makes a right track this way); the Laplace
            envelope is still the seed's.
    """

    def __init__(self, spec: RoadSpec, seed: int, period_m: float | None = None, *,
                 coefficients: np.ndarray | None = None) -> None:
        self.spec = spec
        self.seed = int(seed)
        self.period_m, n_grid = road_grid(spec, period_m)
        self.dx_m = self.period_m / n_grid  # at most spec.dx_m
        if coefficients is None:
            coefficients = iso_coefficients(spec, *spectrum(spec, self.period_m, n_grid),
                                            np.random.default_rng([self.seed, 0]))
        elif np.shape(coefficients) != (n_grid // 2 + 1,):
            raise ValueError(f"coefficients must have shape ({n_grid // 2 + 1},), got "
                             f"{np.shape(coefficients)}")
        # The periodic ISO profile on the grid (eqs 4-6, 4-7), via one inverse FFT:
        # irfft(X)[j] = (1/N) sum_k X_k e^{2 pi i k j / N} (hermitian) -> X_k = N/2 * coeff_k;
        # divided by the cubic interpolation's response, so that the profile read between the
        # grid points has the road's spectrum, not the interpolation's attenuation of it
        gain = catmull_rom_response(np.arange(n_grid // 2 + 1) / n_grid)
        self._grid = sfft.irfft(coefficients * (n_grid / 2.0) / gain, n=n_grid)
        self._sections: dict[int, np.ndarray] = {}

    def heights(self, s_m: np.ndarray) -> np.ndarray:
        """Road height [m] at distances ``s_m`` [m] (any shape, any order)."""
        s = np.asarray(s_m, dtype=float)
        n_grid = self._grid.size
        pos = np.mod(s / self.dx_m, n_grid)
        i0 = np.floor(pos).astype(np.intp)
        frac = pos - i0
        i0 %= n_grid  # pos can round up to n_grid
        g = self._grid
        before, p0, p1, after = g[(i0 - 1) % n_grid], g[i0], g[(i0 + 1) % n_grid], g[(i0 + 2) % n_grid]
        # Catmull-Rom: the cubic through p0, p1 with slopes (p1 - before)/2, (after - p0)/2
        h = p0 + 0.5 * frac * ((p1 - before) + frac * ((2.0 * before - 5.0 * p0 + 4.0 * p1 - after)
                                                        + frac * (3.0 * (p0 - p1) + after - before)))
        if self.spec.kind == "laplace":
            h = h * self.envelope(s)
        return h

    def envelope(self, s_m: np.ndarray) -> np.ndarray:
        """The Laplace road's amplitude envelope sqrt(Y) at ``s_m`` (1 for ISO roads)."""
        s = np.asarray(s_m, dtype=float)
        spec = self.spec
        if spec.kind != "laplace" or spec.laplace_nu == 0.0:
            return np.ones_like(s)
        length = spec.section_length_m
        section = np.floor(s / length).astype(np.int64)
        local = s - section * length
        # Blend toward the neighbouring section within half a ramp of a boundary.
        neighbour = np.where(local < 0.5 * length, section - 1, section + 1)
        dist = np.minimum(local, length - local)  # to the nearest boundary
        ramp = max(spec.envelope_ramp_m, 1e-12)  # a zero ramp is a plain step
        t = np.clip(0.5 - dist / ramp, 0.0, 0.5)
        weight = 0.5 * (1.0 - np.cos(np.pi * t))  # raised cosine, 0.5 on the boundary
        own = self._section_amplitudes(section)
        other = self._section_amplitudes(neighbour)
        return own + (other - own) * weight

    def _section_amplitudes(self, sections: np.ndarray) -> np.ndarray:
        """sqrt(Y_k) for each section index k (integer array)."""
        first = int(sections.min()) // _CHUNK
        last = int(sections.max()) // _CHUNK
        table = np.concatenate([self._chunk_amplitudes(c) for c in range(first, last + 1)])
        return table[sections - first * _CHUNK]

    def _chunk_amplitudes(self, chunk: int) -> np.ndarray:
        """sqrt(Y) of the ``_CHUNK`` sections of one chunk.

        Each chunk has a random stream keyed by its index, so any section can be asked
        for first and its value never changes.
        """
        if chunk not in self._sections:
            if len(self._sections) > 64:  # bounded memory on endless runs
                self._sections.clear()
            rng = np.random.default_rng([self.seed, 1, chunk & 0x7FFFFFFFFFFFFFFF])
            nu = self.spec.laplace_nu
            self._sections[chunk] = np.sqrt(rng.gamma(1.0 / nu, nu, size=_CHUNK))
        return self._sections[chunk]

    @property
    def std_m(self) -> float:
        """RMS height of the ISO base profile [m] (before any Laplace envelope)."""
        return float(np.std(self._grid))
