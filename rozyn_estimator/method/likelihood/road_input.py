"""How one road reaches both axles: :func:`delay_characteristic`, the rear wheel's delay
behind the front over a window's speed profile; and how far it reaches in frequency:
:func:`spatial_band`; and how alike the left and right tracks are: :func:`track_coherence`."""

from __future__ import annotations

import functools

import numpy as np
from scipy import special

from rozyn_estimator.method.likelihood.kept import Kept
from rozyn_estimator.method.likelihood.spectra import taper_window


def delay_characteristic(omega: np.ndarray, wheelbase_m: float, speed_mps: float | np.ndarray,
                         sample_weights: np.ndarray | None = None) -> np.ndarray:
    """φ(ω) = E[exp(-iωτ)], τ = L/v, over the samples' speeds weighted by speed and by
    ``sample_weights`` (the taper's square: what each sample counts for in the periodogram).

    The road velocity's intensity grows with speed (white in time at ``w = 2``), so a
    faster stretch weighs more, and a standing one (``v = 0``) not at all: a tapered window's
    periodogram expects the samples' local spectra averaged with these weights. A constant
    speed gives the exact wheelbase delay.
    """
    v = np.atleast_1d(np.asarray(speed_mps, dtype=float))
    if np.ptp(v) <= 1e-9 * v.mean():  # as ever (the recorded sample bags replay bit for bit)
        return np.exp(-1j * omega * wheelbase_m / v.mean())
    tau, weights = _delays(wheelbase_m, v, sample_weights)
    return np.exp(-1j * np.multiply.outer(omega, tau)) @ weights


def delay_slope(omega: np.ndarray, wheelbase_m: float, speed_mps: float | np.ndarray,
                sample_weights: np.ndarray | None = None) -> np.ndarray:
    """dφ/dL of :func:`delay_characteristic`: every delay ``τ = L/v`` scales with ``L`` (the
    weights stay), so ``dφ/dL = E[-iω τ/L exp(-iωτ)]``."""
    tau, weights = _delays(wheelbase_m, speed_mps, sample_weights)
    arg = -1j * np.multiply.outer(omega, tau)
    return (arg * np.exp(arg)) @ weights / wheelbase_m


def _delays(wheelbase_m: float, speed_mps: float | np.ndarray, sample_weights: np.ndarray | None = None,
            fs_hz: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(the delays τ [s], their weights summing to 1): one for a constant speed, else the
    delays' distribution on :data:`DELAY_BINS` bins weighted by speed and the samples' weights
    (cheap, and exact to far below the band); samples slower than :data:`DRIVING_MPS` count as
    standing. With the samples' rate ``fs_hz`` each delay is the time the front wheel took to
    the rear's place (:func:`travel_delays`), else ``L/v``."""
    v = np.atleast_1d(np.asarray(speed_mps, dtype=float))
    if np.ptp(v) <= 1e-9 * v.mean():
        return np.array([wheelbase_m / v.mean()]), np.ones(1)
    w = v if sample_weights is None else v * np.asarray(sample_weights, dtype=float)
    tau, bins = delay_bins(wheelbase_m, v, fs_hz)
    if tau.size == 0:  # no driving: no road
        return np.array([wheelbase_m / DRIVING_MPS]), np.zeros(1)
    weights = np.bincount(bins[bins >= 0], weights=w[bins >= 0], minlength=tau.size)
    return tau, weights / weights.sum()


DELAY_BINS = 64  # a varying drive's wheelbase delays, binned


def delay_bins(wheelbase_m: float, speed_mps: np.ndarray,
               fs_hz: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(the bins' delays τ [s] (none where nothing is driven; one for one speed), each sample's
    bin (-1: not :func:`steady_driving`)) of a varying drive's samples: :data:`DELAY_BINS`
    equal bins over the driven samples' delays (:func:`travel_delays`; ``L/v`` without ``fs_hz``).
    Read-only, the last few kept: the window's mixture and its stretches both ask."""
    v = np.atleast_1d(np.asarray(speed_mps, dtype=float))
    return _BINS.get((v, wheelbase_m, fs_hz), lambda: _read_only(_binned(wheelbase_m, v, fs_hz)))


def _binned(wheelbase_m: float, v: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    tau, moving = _drive_profile(wheelbase_m, v, fs_hz)
    bins = np.full(v.size, -1)
    if not np.any(moving):
        return np.zeros(0), bins
    driven = tau[moving]
    if np.ptp(driven) <= 1e-6 * driven.mean():  # one speed while driving (the delays' rounding: 4e-8)
        bins[moving] = 0
        return driven[:1], bins
    edges = np.histogram_bin_edges(driven, bins=DELAY_BINS)
    bins[moving] = np.clip(np.searchsorted(edges, driven, side="right") - 1, 0, DELAY_BINS - 1)
    return 0.5 * (edges[:-1] + edges[1:]), bins


def travel_delays(wheelbase_m: float, speed_mps: np.ndarray, fs_hz: float) -> np.ndarray:
    """Each sample's wheelbase delay [s] on a varying drive: how long ago the front wheel was
    where the rear one is (the distance the speed integrates to), not ``L/v``, which is 30 %
    off when pulling away at 3 m/s and 1.5 m/s². Before the window's start the speed is taken
    as its first sample's."""
    v = np.asarray(speed_mps, dtype=float)
    t = np.arange(v.size) / fs_hz
    s = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) / fs_hz)))
    rises = np.maximum.accumulate(s + 1e-9 * t)  # strictly increasing: a stop's last moment wins
    back = s - wheelbase_m
    before = back < 0
    t_front = np.interp(back, rises, t)
    t_front[before] = back[before] / max(float(v[0]), DRIVING_MPS)
    return t - t_front


DRIVING_MPS = 2.0
"""Slower samples of a varying drive count as standing: their road is weak (its power grows with
the speed), and their wheelbase delay, above 1.4 s, turns the front/rear phase faster with
frequency than the model's grid resolves (the mixture's spectrum then interpolates to a
matrix that is not positive definite)."""


STRETCH = 0.03
"""A sample whose rear wheel meets the front's road at a speed this share off is not steady
driving: its rear input is the front's stretched in time (pulling away, braking), which the
model of a delayed copy does not hold; measured, a window with one stop read I_yy 2.5 % low
(mean z -2.1 over 8 roads) with 10 % and no bias with 3 %, the data of such samples masked."""


def steady_driving(wheelbase_m: float, speed_mps: np.ndarray, fs_hz: float) -> np.ndarray:
    """Which samples of a varying drive the model holds: driving (:data:`DRIVING_MPS`), with a
    wheelbase delay of at most ``L / DRIVING_MPS`` and the rear wheel at nearly the front's speed
    (:data:`STRETCH`). The refinement masks the others' data (they hold the model's road nowhere).
    Read-only (kept for the window's other uses)."""
    return _drive_profile(wheelbase_m, np.asarray(speed_mps, dtype=float), fs_hz)[1]


def _drive_profile(wheelbase_m: float, v: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(each sample's wheelbase delay [s], :func:`steady_driving`'s mask), read-only, the last few
    kept: a window's update asks for them about five times (its data's gates, the model's weights,
    its delay bins, its stretches, the model check), each about a third of a millisecond."""
    return _PROFILES.get((v, wheelbase_m, fs_hz), lambda: _profile(wheelbase_m, v, fs_hz))


def _profile(wheelbase_m: float, v: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    tau = travel_delays(wheelbase_m, v, fs_hz) if fs_hz > 0 else wheelbase_m / np.maximum(v, DRIVING_MPS)
    keep = (v >= DRIVING_MPS) & (tau <= wheelbase_m / DRIVING_MPS)  # a delay this long: a crawl
    if fs_hz > 0:
        t = np.arange(v.size) / fs_hz
        v_front = np.interp(t - tau, t, v)
        keep &= np.abs(v / np.maximum(v_front, 1e-9) - 1.0) <= STRETCH
    return _read_only((tau, keep))


def _read_only(pair: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``pair``'s arrays, no longer writeable: a kept result is shared (:class:`Kept`)."""
    for a in pair:
        a.flags.writeable = False
    return pair


def steady_window(accel: np.ndarray, wheelbase_m: float, speed_mps: float | np.ndarray,
                  fs_hz: float, ramp_s: float = 0.0) -> np.ndarray:
    """A window's accelerations as the model of a varying drive holds them: demeaned over its
    :func:`steady_driving` samples and zero elsewhere (at a constant speed: as they are); with
    ``ramp_s``, each steady stretch ramped in and out (:func:`steady_gates`)."""
    if not is_varying(speed_mps):
        return accel
    gates = steady_gates(wheelbase_m, np.asarray(speed_mps, dtype=float), fs_hz, ramp_s)
    keep = gates > 0
    y = np.asarray(accel, dtype=float)
    count = np.count_nonzero(keep)  # the steady samples' mean as a product: a tenth of a masked copy's time
    return gates[:, None] * (y - (keep.astype(float) @ y) / count) if count else y


def steady_gates(wheelbase_m: float, speed_mps: np.ndarray, fs_hz: float, ramp_s: float = 0.0) -> np.ndarray:
    """(n,) 1 on :func:`steady_driving` samples and 0 elsewhere; with ``ramp_s`` > 0 each steady
    stretch rises and falls over a raised cosine of ``ramp_s`` (at most half the stretch) inside
    it: a square gate spreads the body modes' power across the band, a ramp keeps it near them."""
    keep = steady_driving(wheelbase_m, speed_mps, fs_hz).astype(float)
    n_ramp = round(ramp_s * fs_hz)
    if n_ramp < 2 or not np.any(keep):
        return keep
    edges = np.diff(np.concatenate(([0.0], keep, [0.0])))
    starts, stops = np.flatnonzero(edges > 0), np.flatnonzero(edges < 0)
    for lo, hi in zip(starts.tolist(), stops.tolist(), strict=True):  # a stretch per stop: few
        r = min(n_ramp, (hi - lo) // 2)
        if r >= 1:
            rise = 0.5 * (1.0 - np.cos(np.pi * (np.arange(r) + 0.5) / r))
            keep[lo:lo + r] *= rise
            keep[hi - r:hi] *= rise[::-1]
    return keep


def window_weights(n: int, taper: float, wheelbase_m: float, speed_mps: np.ndarray, fs_hz: float,
                   ramp_s: float) -> np.ndarray | None:
    """(n,) each sample's weight in a varying drive's road power: the square of the taper
    (:func:`~rozyn_estimator.method.likelihood.spectra.taper_window`) times the steady
    stretches' gates (:func:`steady_gates`, as :func:`steady_window` cuts the data); None for
    one speed."""
    if np.size(speed_mps) == 1:
        return None
    return (taper_window(n, taper) * steady_gates(wheelbase_m, np.asarray(speed_mps), fs_hz, ramp_s)) ** 2


def unsteady(wheelbase_m: float, speed_mps: float | np.ndarray, fs_hz: float) -> bool:
    """A varying drive's window that :func:`steady_window` masks in part (stops, pulling away)."""
    v = np.asarray(speed_mps, dtype=float)
    return is_varying(v) and not bool(np.all(steady_driving(wheelbase_m, v, fs_hz)))


def driving_speed(speed_mps: float | np.ndarray, sample_weights: np.ndarray | None = None) -> float:
    """The speed the road's power is seen at: the mean over the samples weighted by their
    road power (speed, and ``sample_weights``), ``Σ w v² / Σ w v`` [m/s]; a constant speed itself."""
    v = np.atleast_1d(np.asarray(speed_mps, dtype=float))
    if not is_varying(v):
        return float(v.mean())  # exactly (the products below underflow for a speed of 1e-308)
    w = v if sample_weights is None else v * np.asarray(sample_weights, dtype=float)
    return float(np.sum(w * v) / np.sum(w))


_ROLL_OFF = 0.1  # spatial_band's raised-cosine edge, ± this share of its end frequency


def is_varying(speed_mps: float | np.ndarray) -> bool:
    """A speed per sample that is not one constant."""
    v = np.atleast_1d(np.asarray(speed_mps, dtype=float))
    return bool(np.ptp(v) > 1e-9 * v.mean())


def road_mixture(omega: np.ndarray, wheelbase_m: float, speed_mps: np.ndarray,
                 sample_weights: np.ndarray | None,
                 max_cpm: float, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """A varying drive's road at each frequency: ``(W(ω), φ(ω))``, the share of the window's
    road power there and the front/rear covariance ``E[b exp(-iωτ)]``, both over the samples'
    delays (:func:`travel_delays`, at the samples' rate ``fs_hz``) weighted as
    :func:`delay_characteristic`'s and by ``b``, the road's band at each speed
    (:func:`spatial_band`: a slow stretch has no road above ``max_cpm v``, in the band too).
    The front/rear covariance of the road velocity is then ``[[W, φ̄], [φ, W]]``."""
    mix = track_mixture(omega, wheelbase_m, 0.0, speed_mps, sample_weights, max_cpm, fs_hz)
    return mix.share, mix.phi


_MIXTURES = Kept(4)  # a window's model and its variants (the budget's, the calibration's) share one
_PROFILES = Kept(4)
_BINS = Kept(4)


def track_mixture(omega: np.ndarray, wheelbase_m: float, track_m: float, speed_mps: np.ndarray,
                  sample_weights: np.ndarray | None, max_cpm: float, fs_hz: float) -> TrackMixture:
    """:class:`TrackMixture` of these arguments, the last few kept: a window's model is built
    again for its variants with the same speeds, and each build costs about one update's tenth."""
    args = (np.asarray(omega), np.asarray(speed_mps), sample_weights, wheelbase_m, track_m, max_cpm, fs_hz)
    return _MIXTURES.get(args, lambda: TrackMixture(omega, wheelbase_m, track_m, speed_mps, sample_weights,
                                                   max_cpm, fs_hz))


class TrackMixture:
    """A varying drive's road on two tracks: :func:`road_mixture`'s ``(W, φ)``, and the tracks'
    coherence mixed with the delays, ``G = Σ p b γ(f/v) [[1, e^(iωτ)], [e^(-iωτ), 1]]`` over the
    delays' bins (each its speed ``L/τ``): the coherence of the left and right tracks falls
    with the spatial frequency, which differs for each speed (``track_m`` the front track).
    Read-only once built (:func:`track_mixture` shares it)."""

    def __init__(self, omega: np.ndarray, wheelbase_m: float, track_m: float, speed_mps: np.ndarray,
                 sample_weights: np.ndarray | None, max_cpm: float, fs_hz: float) -> None:
        tau, p = _delays(wheelbase_m, speed_mps, sample_weights, fs_hz)
        f = np.abs(omega) / (2.0 * np.pi)
        band = _edge(f[:, None], max_cpm * wheelbase_m / tau[None, :]) if max_cpm > 0 else \
            np.ones((f.size, tau.size))
        self.omega, self.tau, self._f, self._track = omega, tau, f, (track_m, wheelbase_m)
        self.weights = band * p  # (F, K)
        self.phase = _phases(omega, tau)  # (F, K) e^(-iωτ) of each bin
        self.share, self.phi = self.weights.sum(axis=1), np.einsum("fk,fk->f", self.weights, self.phase)

    @functools.cached_property
    def x(self) -> np.ndarray:
        """(F, K) ``2π n B`` of each bin (built when the tracks' coherence first needs it)."""
        track_m, wheelbase_m = self._track
        return 2.0 * np.pi * self._f[:, None] * track_m * self.tau[None, :] / wheelbase_m

    def parts(self, groups: np.ndarray, scale: float | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """The road of each group of delay bins alone, weighted as in the whole (the drive's
        stretches at those speeds: their shares of the whole sum to it): ``(the axles' delay
        [[W, φ̄], [φ, W]] (G, F, 2, 2), and at the tracks' separation scale ``scale`` their
        coherence G (G, F, 2, 2); None without a scale)`` for ``groups`` (G, K) bool."""
        groups = np.asarray(groups, dtype=bool)
        share, phi = groups @ self.weights.T, groups @ (self.weights * self.phase).T  # (G, F)
        delay = np.stack([share, phi.conj(), phi, share], axis=-1).reshape(*share.shape, 2, 2)
        if scale is None:
            return delay, None
        weighted = self.weights * track_coherence(self.x * scale)[0]
        same, rear = groups @ weighted.T, groups @ (weighted * self.phase).T
        return delay, np.stack([same, rear.conj(), rear, same], axis=-1).reshape(*same.shape, 2, 2)

    def coherence(self, scale: float) -> tuple[np.ndarray, np.ndarray]:
        """``(G, dG/dc)`` (F, 2, 2) at the tracks' separation scale ``e^c``."""
        gamma, slope = track_coherence(self.x * scale)
        return self._mixed(gamma), self._mixed(slope)

    def _mixed(self, g: np.ndarray) -> np.ndarray:
        same, rear = (self.weights * g).sum(axis=1), (self.weights * g * self.phase).sum(axis=1)
        return np.stack([same, rear.conj(), rear, same], axis=-1).reshape(-1, 2, 2)


def _phases(omega: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """(F, K) ``e^(-iωτ_k)``. The delays' bins are evenly spaced (a histogram's), so each bin's is
    the one before times ``e^(-iωΔτ)``, a product over the frequencies per bin: a complex
    exponential per frequency and bin took 13 times as long (0.90 against 0.07 ms on 440 × 64;
    numpy's cumulative product of complex numbers, along either axis, 2.5 times)."""
    if tau.size < 3 or not np.allclose(np.diff(tau), tau[1] - tau[0], rtol=1e-9, atol=0.0):
        return np.exp(-1j * np.multiply.outer(omega, tau))
    rows = np.empty((tau.size, omega.size), dtype=complex)
    rows[0] = np.exp(-1j * omega * tau[0])
    step = np.exp(-1j * omega * (tau[1] - tau[0]))
    for k in range(1, tau.size):
        np.multiply(rows[k - 1], step, out=rows[k])
    return np.ascontiguousarray(rows.T)


def _edge(f: np.ndarray, end_hz: np.ndarray | float) -> np.ndarray:
    """1 below ``end_hz`` and 0 above, with a raised-cosine edge ±10 % wide (the cosine only
    where it is neither: most of a mixture's frequencies and bins are far from their edge)."""
    x = (f - (1.0 - _ROLL_OFF) * end_hz) / (2.0 * _ROLL_OFF * end_hz)
    out = (x <= 0.0).astype(float)
    edge = (x > 0.0) & (x < 1.0)
    out[edge] = 0.5 * (1.0 + np.cos(np.pi * x[edge]))
    return out


def spatial_band(freq_hz: np.ndarray, speed_mps: float | np.ndarray, max_cpm: float) -> np.ndarray:
    """The share (0..1) of the road's power at ``freq_hz`` when its profile ends at ``max_cpm``
    cycles/m: 1 below ``max_cpm v`` and 0 above, with a raised-cosine edge ±10 % wide (a
    smooth model interpolates well between its grid's nodes); all ones for ``max_cpm`` 0.

    Why: a tyre's contact patch smooths wavelengths shorter than about itself away (ISO
    8608's profiles, and the simulator's, end at 5 cycles/m), so what aliases into the band
    is the road below that frequency only. At 30 km/h (5 cycles/m: 42 Hz) nothing aliases at
    100 Hz; modelled as aliasing, the power the model put at the band's noise floors took
    3 % off the full car's roll inertia with quiet sensors. ``v`` the driving speed. The models
    apply it to the aliases only: in the band the road is kept at every frequency (its end
    falls into the default band below about 11 km/h, which is not modelled).
    """
    f = np.abs(np.asarray(freq_hz, dtype=float))
    if max_cpm <= 0:
        return np.ones(f.shape)
    return _edge(f, max_cpm * driving_speed(speed_mps))


def track_coherence(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(γ, dγ/dc) of the isotropic surface for ``w = 2`` at ``x = 2π n B e^c``:
    ``γ = x K₁(x)`` and, as ``d(x K₁)/dx = -x K₀``, ``dγ/dc = -x² K₀(x)``."""
    xp = np.maximum(x, 1e-300)
    with np.errstate(over="ignore", invalid="ignore"):
        gamma = np.where(x > 0, np.nan_to_num(xp * special.k1(xp), nan=0.0), 1.0)
        slope = np.where(x > 0, np.nan_to_num(-xp * xp * special.k0(xp), nan=0.0), 0.0)
    return np.clip(gamma, 0.0, 1.0), slope
