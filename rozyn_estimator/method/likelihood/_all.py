"""Likelihood refinement: a frequency-domain (Whittle) maximum-likelihood fit of the half car.

Rozyn's pipeline (``pipeline.py``) condenses the data into two modes and fits the
inertia to them; this stage fits the whole 4-DOF half car to the whole front/rear
spectral matrix instead, started from Rozyn's estimate.

Model (all in the frequency domain, vectorised over the grid). Each corner is the
suspension ``z_s = k_s + iω c_s`` on the wheel ``m_t`` on the tyre ``z_t = k_t + iω c_t``
(thesis eqs 3-4 to 3-7, chapter 3). Condensing the wheel exactly, the corner acts on the
body at its axle point ``x_b`` with

    F = -Z(ω) x_b + T(ω) u,   Z = z_s (z_t - ω² m_t) / d,   T = z_s z_t / d,
    d = z_s + z_t - ω² m_t,

``u`` the road height under the wheel. The body, in the axle coordinates
``x_b = [x_sf, x_sr]`` (eqs 3-8, 3-9), has the mass matrix (from its kinetic energy)

    M_ax = [[m lr² + I, m lf lr - I], [m lf lr - I, m lf² + I]] / L²,

so ``(diag Z - ω² M_ax) x_b = diag(T) u`` (the 2-DOF equivalent of eqs 2-23 to 2-30 with
the exact dynamic condensation). A sensor at ``x`` from the front axle reads
``-ω² [(1 - x/L), x/L] x_b``. One road drives both wheels: the rear sees the front's
road ``τ = L / v`` later, and the road *velocity* is white for ISO 8608 waviness
``w = 2`` (spectrum ``∝ f^(2-w)`` in general). Per unit road velocity at the front wheel
the accelerations are ``G(ω) [1, e^(-iωτ)]ᵀ`` with ``G = iω P (diag Z - ω² M_ax)⁻¹ diag T``,
and the (two-sided) spectral matrix of the sampled signals is

    S(f) = σ² Σ_a r(f_a) G(ω_a) R(ω_a) G(ω_a)ᴴ + diag(n_f, n_r),   f_a = f + a·fs,

``R = [[1, φ̄], [φ, 1]]`` with ``φ = E[e^(-iωτ)]`` over the window's speed profile (rank
one at constant speed), ``r = |f / f_ref|^(2-w) exp(Σ c_d P_d(x))`` the road's shape (ISO
8608's power law times smooth departures, ``P_d`` Legendre polynomials of degree ≥ 2 in
log frequency ``x`` across the band), the sum over ``a = -A..A`` the aliasing of
instantaneous sampling, and ``n_f, n_r`` white sensor noise. Optionally a share ``ε`` of
the road part's diagonal is added as incoherent between the channels (a model-error
floor; useful only on nearly noise-free data, where nothing else limits the coherence).

Fit. The negative Whittle log-likelihood of the window's periodogram matrices ``I_k``
at the Fourier frequencies ``f_k`` of the band (default 0.5-15 Hz, and at most 60 % of the
Nyquist frequency)

    ℓ(θ) = Σ_k log det S_k + tr(S_k⁻¹ I_k)

is minimised over ``θ = [ln m, ln I, logit(lf/L), ln σ², ln n_f, ln n_r, w, c_2..c_5]``
(optionally ``ln ε`` and the log scale factors of the suspension stiffness and damping as
well) by scipy's
trust-region Newton method with the analytic gradient. Its Hessian is the Fisher
information far from the optimum and, near it, the Fisher information with the exact
rows of ``σ²`` and the noise floors (their second derivatives are known in closed form);
the fit stops when the Newton decrement ``gᵀF⁻¹g`` is below ``tol``. ``spectra="auto"``
uses the auto-spectra only (for comparison).

Starts and the guard against wrong basins (a basin that explains one channel as noise
exists): cold, the fit runs from the given start (Rozyn's estimate) and from the best
point of a coarse grid of body frequencies and CoG positions, and keeps the lower ℓ;
warm, from the previous window's optimum, and from the given start too when the result
disagrees with it by more than 6 of its standard deviations. A result that still
explains a channel as mostly noise is refused.

Covariance: the sandwich ``H⁻¹ J H⁻¹`` mapped to (m, I, lf), with ``H`` the Fisher
information (``covariance="expected"``, free) or the observed information (the Hessian of
ℓ by forward differences of the analytic gradient, ``"observed"``), and ``J`` the
covariance of the score under the fitted model: with no taper and both cross-spectra that
is the Fisher information itself; it adds what the taper correlates (neighbouring
ordinates) and, for the auto-spectra fit, the channels' correlation that fit ignores. A
noise floor run to zero (noise-free data) is held fixed. That ``J`` assumes a stationary
road; on a road whose roughness changes along the way (the Laplace road) the estimate
varies more. So the score's variance is also measured from the data: the score is a
quadratic form of the samples, split over ~12 s time blocks, whose spread (batch means,
the road intensity's drift regressed out) estimates it whatever the road; the published
``J`` is the mean of the model's and the blocks' (``block_weight``, see ``_covariance``).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import legendre
from scipy import fft as sfft
from scipy.optimize import OptimizeResult, minimize
from scipy.signal import windows

from rozyn_estimator.method.likelihood.config import LikelihoodConfig
from rozyn_estimator.vehicle import Vehicle

_CORNERS = ("front", "rear")
_NOISE_AT_ZERO = 1e-5  # a noise floor below this share of its channel's band power is zero
_MIN_NOISE = 1e-9  # the model's fixed white floor, share of each channel's band power
_GRID_HZ = (0.8, 1.2, 1.8)  # body frequencies of the coarse start grid
_NEAR = 10.0  # Newton decrement below which the optimiser uses the sharper Hessian
_INCOHERENCE_START = 1e-4
_INCOHERENCE_AT_ZERO = 1e-6


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
    w = windows.tukey(n, taper) if taper > 0 else np.ones(n)
    w = w / np.sqrt(np.mean(w * w))
    freq = np.arange(n // 2 + 1) * (fs_hz / n)
    keep = (freq >= band_hz[0]) & (freq <= band_hz[1])
    d = sfft.rfft(y * w[:, None], axis=0)[keep]
    per = d[:, :, None] * d[:, None, :].conj() / (n * fs_hz)
    w_hat = sfft.fft(w) / n  # Σ |ŵ|² = mean(w²) = 1 (Parseval)
    c = np.abs(w_hat) ** 2
    half = int(np.argmax(np.cumsum(c[: n // 2] + np.r_[0.0, c[:0:-1][: n // 2 - 1]]) >= 1.0 - 1e-4))
    window_dft = np.r_[w_hat[n - half:] if half else np.zeros(0, dtype=complex), w_hat[: half + 1]]
    return Spectra(freq_hz=freq[keep], periodogram=per, fs_hz=float(fs_hz), n_samples=n,
                   window_dft=window_dft, dft=d, first_bin=int(np.argmax(keep)))


def delay_characteristic(
    omega: np.ndarray, wheelbase_m: float, speed_mps: float | np.ndarray
) -> np.ndarray:
    """φ(ω) = E[exp(-iωτ)], τ = L/v, over the samples' speeds weighted by speed.

    The road velocity's intensity grows with speed (white in time at ``w = 2``), so a
    faster stretch weighs more. A constant speed gives the exact wheelbase delay.
    """
    v = np.atleast_1d(np.asarray(speed_mps, dtype=float))
    if np.ptp(v) <= 1e-9 * v.mean():
        return np.exp(-1j * omega * wheelbase_m / v.mean())
    # The delays' distribution on 64 bins: cheap, and exact to far below the band.
    weights, edges = np.histogram(wheelbase_m / v, bins=64, weights=v)
    tau = 0.5 * (edges[:-1] + edges[1:])
    return np.exp(-1j * np.multiply.outer(omega, tau)) @ (weights / weights.sum())


class HalfCarSpectrum:
    """The half car's spectral matrix and its derivatives on a frequency grid.

    Args:
        vehicle: known suspension, tyres, unsprung masses, geometry and sensor positions.
        freq_hz: (k,) the grid [Hz].
        fs_hz: sample rate [Hz] (for the aliasing terms).
        speed_mps: speed, constant or per sample [m/s].
        aliases: aliasing terms ``a = -A..A``.
        f_ref_hz: reference frequency of the road shape ``|f/f_ref|^(2-w)``.
        estimate_waviness, road_shape_terms, estimate_suspension, estimate_incoherence:
            which nuisance parameters θ holds (see :class:`LikelihoodConfig`).
        min_noise_psd: (front, rear) white floor added to the fitted noise [(m/s²)²/Hz]:
            keeps S positive definite when the data are noise-free (θ's noise floor then
            runs to zero and stops mattering).
    """

    def __init__(
        self, vehicle: Vehicle, freq_hz: np.ndarray, fs_hz: float, speed_mps: float | np.ndarray,
        aliases: int = 1, f_ref_hz: float = 3.0, estimate_waviness: bool = False,
        estimate_suspension: bool = False, min_noise_psd: tuple[float, float] = (0.0, 0.0),
        road_shape_terms: int = 0, estimate_incoherence: bool = False,
        window_weights: np.ndarray | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.n_freq = freq_hz.size
        self.wheelbase_m = L = vehicle.wheelbase_m
        # A tapered periodogram's expectation is S smoothed by the taper's spectral window:
        # the model runs on the grid extended by J Fourier bins each side (above 0 Hz).
        c = np.ones(1) if window_weights is None else np.asarray(window_weights, dtype=float)
        half = (c.size - 1) // 2
        df = freq_hz[1] - freq_hz[0] if freq_hz.size > 1 else 1.0
        room = max(0, math.ceil(freq_hz[0] / df) - 1)
        if half > room:
            c = c[half - room: half + room + 1]
            half = room
        self.kernel = c / c.sum()
        self.half = half
        self.n_ext = freq_hz.size + 2 * half
        grid = freq_hz[0] + df * np.arange(-half, freq_hz.size + half) if half else freq_hz
        shifts = np.arange(-aliases, aliases + 1)[:, None] * fs_hz
        f = (grid[None, :] + shifts).ravel()  # (A (k + 2J),) signed
        self.n_alias = 2 * aliases + 1
        self.omega = w = 2.0 * np.pi * f
        self.log_shape = np.log(np.abs(f) / f_ref_hz)  # road shape r = exp((2 - w) log_shape + ...)
        # Legendre polynomials of degree 2.. in log frequency across the band (held at
        # their edge values outside it, e.g. at the aliases): the road's departure from a
        # power law.
        edges = np.log(np.array([freq_hz.min(), freq_hz.max()]) / f_ref_hz)
        x = np.clip((2.0 * self.log_shape - edges.sum()) / (edges[1] - edges[0]), -1.0, 1.0)
        self.shape_basis = np.array([legendre.legval(x, np.eye(road_shape_terms + 2)[d])
                                     for d in range(2, road_shape_terms + 2)])
        phi = delay_characteristic(w, L, speed_mps)
        # Front/rear road velocity covariance R = [[1, φ̄], [φ, 1]] = C Cᴴ, C lower triangular;
        # at constant speed |φ| = 1 and the second column vanishes.
        self.inputs = [np.array([np.ones_like(phi), phi])]
        spread = 1.0 - np.abs(phi) ** 2
        if np.max(spread) > 1e-12:
            self.inputs.append(np.array([np.zeros_like(phi), np.sqrt(np.maximum(spread, 0.0))]))
        x = np.asarray(vehicle.sensor_x_m)
        self.sensor_map = np.column_stack([1.0 - x / L, x / L])  # P: axle -> sensor heave
        v = vehicle
        self.ks0 = np.array([v.suspension_stiffness_front_npm, v.suspension_stiffness_rear_npm])
        self.cs0 = np.array([v.suspension_damping_front_nspm, v.suspension_damping_rear_nspm])
        kt = np.array([v.tyre_stiffness_front_npm, v.tyre_stiffness_rear_npm])
        ct = np.array([v.tyre_damping_front_nspm, v.tyre_damping_rear_nspm])
        mt = np.array([v.unsprung_mass_front_kg, v.unsprung_mass_rear_kg])
        self.z_tyre = kt + 1j * w[:, None] * ct  # (A k, 2)
        self.w_tyre = self.z_tyre - (w * w)[:, None] * mt  # tyre minus wheel inertia
        self.min_noise_psd = np.asarray(min_noise_psd, dtype=float)
        self.estimate_waviness = estimate_waviness
        self.estimate_suspension = estimate_suspension
        self.names = ["ln_mass", "ln_inertia", "logit_cog", "ln_road", "ln_noise_front", "ln_noise_rear"]
        if estimate_incoherence:
            self.names.append("ln_incoherence")
        if estimate_waviness:
            self.names.append("waviness")
        first_shape = len(self.names)
        self.names += [f"road_shape_{d}" for d in range(2, road_shape_terms + 2)]
        self.shape_slice = slice(first_shape, first_shape + road_shape_terms)
        if estimate_suspension:
            self.names += [f"ln_{q}_{c}" for q in ("stiffness", "damping") for c in _CORNERS]
        self.n_params = len(self.names)
        self.index = {name: k for k, name in enumerate(self.names)}

    # --- parameters -------------------------------------------------------------------
    def theta(
        self, params: np.ndarray, road: float, noise: np.ndarray, waviness: float = 2.0
    ) -> np.ndarray:
        """θ from (m, I, lf), road intensity σ² and noise floors (n_f, n_r)."""
        m, inertia, lf = params
        p = lf / self.wheelbase_m
        th = [math.log(m), math.log(inertia), math.log(p / (1.0 - p)), math.log(road), *np.log(noise)]
        if "ln_incoherence" in self.index:
            th.append(math.log(_INCOHERENCE_START))
        if self.estimate_waviness:
            th.append(waviness)
        th += [0.0] * self.shape_basis.shape[0]
        if self.estimate_suspension:
            th += [0.0] * 4
        return np.array(th)

    def physical(self, theta: np.ndarray) -> np.ndarray:
        """(m [kg], I [kg m²], lf [m]) from θ."""
        p = 1.0 / (1.0 + math.exp(-theta[2]))
        return np.array([math.exp(theta[0]), math.exp(theta[1]), p * self.wheelbase_m])

    def physical_jacobian(self, theta: np.ndarray) -> np.ndarray:
        """(3, n_params) d(m, I, lf)/dθ."""
        m, inertia, lf = self.physical(theta)
        p = lf / self.wheelbase_m
        jac = np.zeros((3, self.n_params))
        jac[0, 0], jac[1, 1], jac[2, 2] = m, inertia, self.wheelbase_m * p * (1.0 - p)
        return jac

    def _mass_matrix(self, theta: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """M_ax (2, 2) and its derivatives by (ln m, ln I, logit lf/L)."""
        m, inertia, lf = self.physical(theta)
        L = self.wheelbase_m
        lr = L - lf
        heave = np.array([[lr * lr, lf * lr], [lf * lr, lf * lf]]) / L**2
        pitch = np.array([[1.0, -1.0], [-1.0, 1.0]]) / L**2
        d_lf = np.array([[-2.0 * lr, lr - lf], [lr - lf, 2.0 * lf]]) / L**2
        p = lf / L
        return m * heave + inertia * pitch, [m * heave, inertia * pitch, m * d_lf * L * p * (1.0 - p)]

    # --- the model ----------------------------------------------------------------------
    def spectrum(
        self, theta: np.ndarray, derivatives: bool = True, smooth: bool = True
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """S (k, 2, 2) and, if asked, dS/dθ (n_params, k, 2, 2).

        ``smooth=False``: S on the extended grid (k + 2J), without the taper's smoothing
        (no derivatives).

        With ``R = C Cᴴ`` (``C`` the columns of :attr:`inputs`), ``G R Gᴴ = Σ_c g_c g_cᴴ``
        with ``g_c = iω P x_c``, ``x_c = H (T ⊙ C_c)``, ``H = (diag Z - ω² M_ax)⁻¹``: every
        quantity is a 2-vector per frequency, and a derivative of ``H`` needs no solve
        (``∂x = -H ∂D x + H (∂T ⊙ C_c)``).
        """
        w = self.omega
        w2 = w * w
        scale = np.exp(theta[-4:]) if self.estimate_suspension else np.ones(4)
        ks, cs = self.ks0 * scale[:2], self.cs0 * scale[2:]
        zs = ks + 1j * w[:, None] * cs  # (F, 2) suspension
        den = zs + self.w_tyre
        Z = zs * self.w_tyre / den  # condensed corner stiffness
        T = zs * self.z_tyre / den  # road height -> force on the body
        mass, d_mass = self._mass_matrix(theta)
        d11 = Z[:, 0] - w2 * mass[0, 0]  # D = diag(Z) - ω² M_ax (complex symmetric)
        d22 = Z[:, 1] - w2 * mass[1, 1]
        d12 = -w2 * mass[0, 1]
        det = d11 * d22 - d12 * d12
        H = np.array([[d22, -d12], [-d12, d11]]) / det  # (2, 2, F)
        P = self.sensor_map
        iw = 1j * w
        Q = iw * np.einsum("ab,bcf->acf", P, H)  # iω P H
        exponent = ((2.0 - theta[self.index["waviness"]]) if self.estimate_waviness else 0.0) * self.log_shape
        weight = math.exp(theta[3]) * np.exp(exponent + theta[self.shape_slice] @ self.shape_basis)
        u = [T.T * c for c in self.inputs]  # T ⊙ C_c, each (2, F)
        x = [np.einsum("abf,bf->af", H, uc) for uc in u]
        g = [iw * (P @ xc) for xc in x]
        rank = self._outer_sum(g, g, weight)
        if smooth:
            rank = self._smooth(rank)
        k_inc = self.index.get("ln_incoherence")
        incoherence = math.exp(theta[k_inc]) if k_inc is not None else 0.0
        S_road = rank + incoherence * self._diagonal(rank)
        noise = np.exp(theta[4:6])
        S = S_road.copy()
        S[:, 0, 0] += noise[0] + self.min_noise_psd[0]
        S[:, 1, 1] += noise[1] + self.min_noise_psd[1]
        if not (derivatives and smooth):
            return S, None
        road = []  # ∂(rank part) on the extended grid, in the order of θ's road parameters
        for j in range(3):  # ∂D = -ω² dM: ∂g = ω² Q dM x
            dg = [w2 * np.einsum("abf,bf->af", Q, d_mass[j] @ xc) for xc in x]
            road.append(self._hermitian_part(self._outer_sum(dg, g, weight)))
        if self.estimate_waviness:
            road.append(self._outer_sum(g, g, -weight * self.log_shape))
        road += [self._outer_sum(g, g, weight * basis) for basis in self.shape_basis]
        if self.estimate_suspension:
            # ∂g = Q (∂T ⊙ C_c - ∂Z ⊙ x_c); ∂Z, ∂T are diagonal, so only corner k's entry.
            dZ_dzs = (self.w_tyre / den) ** 2
            dT_dzs = self.z_tyre * self.w_tyre / den**2
            for dzs in (np.broadcast_to(ks, zs.shape), iw[:, None] * cs):  # ∂z_s/∂ln k_s, ∂ln c_s
                for k in range(2):
                    dZ, dT = dzs[:, k] * dZ_dzs[:, k], dzs[:, k] * dT_dzs[:, k]
                    dg = [Q[:, k] * (dT * c[k] - dZ * xc[k]) for c, xc in zip(self.inputs, x, strict=True)]
                    road.append(self._hermitian_part(self._outer_sum(dg, g, weight)))
        dS = np.zeros((self.n_params, self.n_freq, 2, 2), dtype=complex)
        road_rows = [k for k in range(self.n_params) if k not in (3, 4, 5) and k != k_inc]
        smoothed = self._smooth(np.stack(road))
        dS[road_rows] = smoothed + incoherence * self._diagonal(smoothed)
        dS[3] = S_road
        dS[4, :, 0, 0] = noise[0]
        dS[5, :, 1, 1] = noise[1]
        if k_inc is not None:
            dS[k_inc] = incoherence * self._diagonal(rank)
        return S, dS

    def _smooth(self, m: np.ndarray) -> np.ndarray:
        """The taper's spectral window applied along frequency: (..., k + 2J, 2, 2) -> (..., k, 2, 2)."""
        if self.kernel.size == 1:
            return m
        k = self.n_freq
        return sum(c * m[..., j: j + k, :, :] for j, c in enumerate(self.kernel))

    @staticmethod
    def _diagonal(m: np.ndarray) -> np.ndarray:
        """The diagonal part of stacked 2x2 matrices (..., 2, 2)."""
        out = np.zeros_like(m)
        out[..., 0, 0], out[..., 1, 1] = m[..., 0, 0], m[..., 1, 1]
        return out

    def _outer_sum(self, a: list[np.ndarray], b: list[np.ndarray], weight: np.ndarray) -> np.ndarray:
        """Σ_c weight a_c b_cᴴ folded over the aliases: (k + 2J, 2, 2) on the extended grid."""
        out = sum(np.einsum("af,bf->fab", ac, bc.conj()) for ac, bc in zip(a, b, strict=True))
        return (weight[:, None, None] * out).reshape(self.n_alias, self.n_ext, 2, 2).sum(axis=0)

    @staticmethod
    def _hermitian_part(m: np.ndarray) -> np.ndarray:
        """m + mᴴ per frequency."""
        return m + m.conj().transpose(0, 2, 1)


def _inv2(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(inverse, real determinant) of a stack of 2x2 Hermitian matrices."""
    det = (S[:, 0, 0] * S[:, 1, 1]).real - np.abs(S[:, 0, 1]) ** 2
    inv = np.empty_like(S)
    inv[:, 0, 0], inv[:, 1, 1] = S[:, 1, 1] / det, S[:, 0, 0] / det
    inv[:, 0, 1], inv[:, 1, 0] = -S[:, 0, 1] / det, -S[:, 1, 0] / det
    return inv, det


def _curvatures(inv: np.ndarray, dS: np.ndarray, SiI: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Fisher information, the Hessian of ℓ without the terms of ∂²S).

    With ``V_i = S⁻¹ ∂_i S`` and ``M = S⁻¹ I``: Fisher ``Σ_k tr(V_i V_j)``; the Hessian
    part ``Σ_k tr(V_i V_j M) + tr(V_j V_i M) - tr(V_i V_j)`` (its expectation, at ``M = 1``,
    is the Fisher information).
    """
    V = inv[None, :, :, :1] * dS[:, :, None, 0] + inv[None, :, :, 1:] * dS[:, :, None, 1]
    p = V.shape[0]
    rows = V.reshape(p, -1)
    fisher = (rows @ V.transpose(0, 1, 3, 2).reshape(p, -1).T).real
    VM = V[..., :1] * SiI[None, :, None, 0] + V[..., 1:] * SiI[None, :, None, 1]
    B = (rows @ VM.transpose(0, 1, 3, 2).reshape(p, -1).T).real
    return fisher, B + B.T - fisher


def _ridged(m: np.ndarray) -> np.ndarray:
    """``m`` plus a ridge of 1e-10 of its largest diagonal entry (flat directions stay still)."""
    return m + 1e-10 * np.max(np.abs(np.diag(m))) * np.eye(m.shape[0])


class WhittleObjective:
    """ℓ(θ), its gradient and the Fisher information, with the last evaluation cached."""

    def __init__(self, model: HalfCarSpectrum, spectra: Spectra, spectra_kind: str = "cross") -> None:
        self.model = model
        self.auto = spectra_kind == "auto"
        per = spectra.periodogram
        self.periodogram = self._restrict(per)
        self.band_power = _band_power(spectra)
        self.window_dft = spectra.window_dft
        self.spectra = spectra
        self._key: bytes | None = None
        self._value: tuple[float, np.ndarray] | None = None
        self._parts: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._curv: tuple[np.ndarray, np.ndarray] | None = None

    def _restrict(self, m: np.ndarray) -> np.ndarray:
        if not self.auto:
            return m
        out = np.zeros_like(m)
        out[..., 0, 0], out[..., 1, 1] = m[..., 0, 0], m[..., 1, 1]
        return out

    def nll(self, S: np.ndarray) -> float:
        """ℓ for a model spectrum ``S`` (k, 2, 2); inf where S is not positive definite."""
        return self._nll(self._restrict(S))[0]

    def _nll(self, S: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """(ℓ, S⁻¹, S⁻¹ I) from the model's S."""
        inv, det = _inv2(S)
        if not (np.all(np.isfinite(det)) and np.all(det > 0)):
            return math.inf, inv, inv
        SiI = inv @ self.periodogram
        return float(np.sum(np.log(det)) + np.einsum("kaa->", SiI).real), inv, SiI

    def evaluate(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """(ℓ, ∇ℓ) at θ; ℓ = inf where S is not positive definite."""
        key = np.asarray(theta, dtype=float).tobytes()
        if key == self._key and self._value is not None:
            return self._value
        S, dS = self.model.spectrum(theta)
        S, dS = self._restrict(S), self._restrict(dS)
        nll, inv, SiI = self._nll(S)
        p = self.model.n_params
        if not math.isfinite(nll):
            value, self._parts = (math.inf, np.zeros(p)), None
        else:
            W = inv - SiI @ inv  # S⁻¹ - S⁻¹ I S⁻¹
            grad = (dS.reshape(p, -1) @ W.transpose(0, 2, 1).ravel()).real  # Σ_k tr(∂S W)
            value, self._parts = (nll, grad), (inv, dS, SiI)
        self._key, self._value, self._curv = key, value, None
        return value

    def fun(self, theta: np.ndarray) -> float:
        return self.evaluate(theta)[0]

    def jac(self, theta: np.ndarray) -> np.ndarray:
        return self.evaluate(theta)[1]

    def _curvatures(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        _, grad = self.evaluate(theta)
        if self._curv is None:
            if self._parts is None:
                eye = np.eye(self.model.n_params)
                self._curv = (eye, eye)
            else:
                fisher, exact = _curvatures(*self._parts)
                # The rows of the parameters that scale a part of S (road intensity, noise
                # floors) are exact: their second derivatives are ∂²S/∂θ_i∂θ_j = ∂S/∂θ_j
                # (the road intensity with every parameter of the road part, each noise
                # floor with itself), whose terms are the gradient's. There the Fisher
                # information can be far off (noise floors are seen at few frequencies);
                # elsewhere the transfer functions' second derivatives matter and it is good.
                road = [j for j in range(self.model.n_params) if j not in (4, 5)]
                exact[3, road] += grad[road]
                exact[road, 3] += grad[road]
                exact[3, 3] -= grad[3]
                exact[4, 4] += grad[4]
                exact[5, 5] += grad[5]
                hess = fisher.copy()
                hess[3:6], hess[:, 3:6] = exact[3:6], exact[:, 3:6]
                self._curv = (fisher, hess)
        return self._curv

    def fisher(self, theta: np.ndarray) -> np.ndarray:
        """The Fisher information at θ (the expected Hessian of ℓ)."""
        return self._curvatures(theta)[0]

    def decrement(self, theta: np.ndarray) -> float:
        """Newton decrement gᵀF⁻¹g: twice the ℓ a scoring step would still gain."""
        _, grad = self.evaluate(theta)
        return float(grad @ np.linalg.solve(_ridged(self.fisher(theta)), grad))

    def hess(self, theta: np.ndarray) -> np.ndarray:
        """The optimiser's Hessian, with a tiny ridge so that a direction the data say
        nothing about (a noise floor run to zero) stays still: far from the optimum the
        Fisher information (scoring, robust); near it (decrement below ``_NEAR``) with the
        exact rows of the road intensity and noise floors (fast final convergence)."""
        fisher, hess = self._curvatures(theta)
        return _ridged(fisher if self.decrement(theta) > _NEAR else hess)

    def observed_information(self, theta: np.ndarray, step: float = 1e-5) -> np.ndarray:
        """Hessian of ℓ at θ by forward differences of the analytic gradient."""
        g0 = self.jac(theta).copy()
        h = np.array([(self.jac(theta + step * e) - g0) / step for e in np.eye(theta.size)]).T
        return 0.5 * (h + h.T)

    def score_covariance(self, theta: np.ndarray, combos: np.ndarray) -> np.ndarray:
        """``combos Cov(∇ℓ) combosᵀ`` under the full (cross-spectral) model at θ.

        ``Cov(g_i, g_j) = Σ_(k,k') Re tr(A_ik C_kk' A_jk' C_k'k)`` with ``A_i = S⁻¹ ∂_i S S⁻¹``
        of the fitted likelihood (diagonal for the auto-spectra fit) and
        ``C_kk' = E[d_k d_k'ᴴ] = Σ_j ŵ_j ŵ*_(j+k'-k) S(f_(k-j))`` (Isserlis' theorem for
        complex Gaussian DFT coefficients). Untapered and cross-spectral it is the Fisher
        information; it adds what the auto-spectra fit ignores (the channels' correlation)
        and what a taper correlates (neighbouring ordinates).

        Args:
            combos: (q, n_params) linear combinations of the score wanted.
        """
        model = self.model
        S_ext, _ = model.spectrum(theta, derivatives=False, smooth=False)
        S, dS = model.spectrum(theta)
        inv = _inv2(self._restrict(S))[0]
        dS = np.tensordot(combos, self._restrict(dS), axes=1)  # (q, k, 2, 2)
        A = inv[None] @ dS @ inv[None]
        half, k = model.half, model.n_freq
        c = np.abs(self.window_dft) ** 2
        centre = (c.size - 1) // 2
        w_hat = self.window_dft[centre - half: centre + half + 1]  # as the model's kernel
        q = A.shape[0]
        out = np.zeros((q, q))
        # Offsets whose window products are all below 1 % add < 1e-4 of J: skipped.
        reach = [d for d in range(2 * half + 1)
                 if np.sum(np.abs(w_hat[: w_hat.size - d] * w_hat[d:])) >= 0.01]
        top = max(reach) if reach else 0
        for delta in range(-top, top + 1):
            # C_(k, k+δ) for the band's k, from S on the extended grid (index k - j + J)
            C = sum(w_hat[j + half] * np.conj(w_hat[j + delta + half]) * S_ext[half - j: half - j + k]
                    for j in range(max(-half, -half - delta), min(half, half - delta) + 1))
            lo, hi = max(0, -delta), min(k, k - delta)
            X = A[:, lo:hi] @ C[None, lo:hi]
            Y = A[:, lo + delta: hi + delta] @ C[None, lo:hi].conj().transpose(0, 1, 3, 2)
            out += (X.reshape(q, -1) @ Y.transpose(0, 1, 3, 2).reshape(q, -1).T).real
        return 0.5 * (out + out.T)


@dataclass(frozen=True)
class Refinement:
    """Result of the likelihood refinement. ``params``/``covariance`` None unless ok."""

    status: str  # "ok" | "failed"
    reason: str = ""
    params: np.ndarray | None = None  # (m [kg], I [kg m²], lf [m])
    covariance: np.ndarray | None = None  # (3, 3)
    theta: np.ndarray | None = None  # all fitted parameters (names in ``names``)
    names: tuple[str, ...] = ()
    neg_log_likelihood: float = math.nan  # ℓ at the optimum (constant terms dropped)
    iterations: int = 0
    starts: int = 0
    band_hz: tuple[float, float] = (math.nan, math.nan)
    noise_std_mps2: tuple[float, float] = (math.nan, math.nan)  # fitted white sensor noise
    waviness: float = 2.0
    suspension_scale: tuple[float, ...] = ()  # fitted (k_s f, k_s r, c_s f, c_s r) / nominal
    variance_factors: tuple[float, ...] = ()  # (m, I, lf) variances / the model sandwich's
    elapsed_ms: float = 0.0
    notes: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "status": self.status, "reason": self.reason,
            "params": None if self.params is None else self.params.tolist(),
            "neg_log_likelihood": self.neg_log_likelihood, "iterations": self.iterations,
            "starts": self.starts, "band_hz": list(self.band_hz),
            "noise_std_mps2": list(self.noise_std_mps2), "waviness": self.waviness,
            "elapsed_ms": self.elapsed_ms,
        }
        if self.suspension_scale:
            out["suspension_scale"] = list(self.suspension_scale)
        return out


def refine(
    accel_mps2: np.ndarray,
    fs_hz: float,
    vehicle: Vehicle,
    start: np.ndarray | None,
    speed_mps: float | np.ndarray,
    config: LikelihoodConfig | None = None,
    warm: Refinement | np.ndarray | None = None,
    start_std: np.ndarray | None = None,
) -> Refinement:
    """Maximum-likelihood (m, I, lf) from a window, started from ``start``.

    Cold (no ``warm``), the fit runs from ``start`` and from the best point of a coarse
    grid, and keeps the lower ℓ. Warm, it runs from the previous optimum, and from
    ``start`` as well only if the result disagrees with it by more than 6 ``start_std``.

    Args:
        accel_mps2: (n, 2) front/rear vertical accelerations on a uniform grid, finite.
        fs_hz: sample rate [Hz].
        vehicle: the known suspension, tyres, unsprung masses, geometry and sensors.
        start: (3,) start (m [kg], I [kg m²], lf [m]), e.g. Rozyn's estimate; None (or
            an unphysical one) for the best point of a coarse grid instead.
        speed_mps: the speed [m/s], a number or one per sample.
        config: settings.
        warm: the previous window's refinement (its full θ, nuisance parameters
            included, is the first start) or its (m, I, lf).
        start_std: (3,) standard deviations of ``start`` (the warm path's guard).

    Returns:
        A :class:`Refinement`, ``failed`` with a reason when no optimum is credible.
    """
    cfg = config or LikelihoodConfig()
    started = time.perf_counter()
    try:
        start = None if start is None else np.asarray(start, dtype=float)
        result = _refine(np.asarray(accel_mps2, dtype=float), float(fs_hz), vehicle, start, start_std,
                         speed_mps, cfg, warm)
    except _FitError as exc:
        result = Refinement(status="failed", reason=str(exc))
    except (np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
        result = Refinement(status="failed", reason=f"likelihood fit: {exc}")
    return _with_time(result, started)


def _with_time(r: Refinement, started: float) -> Refinement:
    return dataclasses.replace(r, elapsed_ms=(time.perf_counter() - started) * 1e3)


class _FitError(Exception):
    """The optimum found is not credible (becomes a failed status)."""


def _refine(
    y: np.ndarray, fs: float, vehicle: Vehicle, start: np.ndarray | None, start_std: np.ndarray | None,
    speed: float | np.ndarray, cfg: LikelihoodConfig, warm: Refinement | np.ndarray | None,
) -> Refinement:
    band = (cfg.band_hz[0], min(cfg.band_hz[1], cfg.max_band_nyquist * fs / 2.0))
    v = np.atleast_1d(np.asarray(speed, dtype=float))
    if not (np.all(np.isfinite(v)) and np.all(v > 0)):
        return Refinement(status="failed", reason="likelihood fit needs a positive speed")
    if v.size not in (1, y.shape[0]):
        return Refinement(status="failed", reason=f"speed: expected 1 or {y.shape[0]} values, got {v.size}")
    L = vehicle.wheelbase_m
    spectra = window_spectra(y, fs, band, cfg.taper)
    if spectra.freq_hz.size < 50:
        return Refinement(status="failed", reason=f"too few frequencies in {band[0]:g}-{band[1]:g} Hz")
    model = HalfCarSpectrum(vehicle, spectra.freq_hz, fs, v if v.size > 1 else float(v[0]), cfg.aliases,
                            f_ref_hz=math.sqrt(band[0] * band[1]),
                            estimate_waviness=cfg.estimate_waviness,
                            estimate_suspension=cfg.estimate_suspension,
                            min_noise_psd=tuple(_MIN_NOISE * _band_power(spectra)),
                            road_shape_terms=cfg.road_shape_terms,
                            estimate_incoherence=cfg.estimate_incoherence,
                            window_weights=spectra.window_weights)
    objective = WhittleObjective(model, spectra, cfg.spectra)
    fits = _Fits(objective, cfg)
    start_ok = start is not None and _physical(start, L)
    warm_theta = None
    if isinstance(warm, Refinement) and warm.theta is not None and warm.theta.size == model.n_params:
        warm_theta = warm.theta
    elif isinstance(warm, np.ndarray) and _physical(warm, L):
        warm_theta = _start_theta(model, spectra, warm, cfg.noise_start)
    if warm_theta is not None:
        # Warm: the previous optimum. The guard (the given start, or the grid's best) runs
        # only when the result disagrees with the start beyond 6 of its standard deviations
        # (Rozyn's are at times optimistic: a wrong basin lies much further away).
        fits.run(warm_theta)
        if cfg.second_start and not _agrees(model.physical(fits.best.x), start, start_std):
            fits.run(_start_theta(model, spectra, start, cfg.noise_start) if start_ok else
                     _grid_starts(objective, spectra, vehicle, cfg.noise_start)[0])
    else:
        # Cold: the given start and the best point of a coarse grid (or the grid's two best).
        starts = [_start_theta(model, spectra, start, cfg.noise_start)] if start_ok else []
        if cfg.second_start or not start_ok:
            starts += _grid_starts(objective, spectra, vehicle, cfg.noise_start)
        for th0 in starts[: 2 if cfg.second_start else 1]:
            fits.run(th0)
    best, iterations = fits.best, fits.iterations
    if best is None or not np.isfinite(best.fun):
        return Refinement(status="failed", reason="likelihood fit: no start gave a finite likelihood")
    theta = best.x
    params = model.physical(theta)
    notes: list[str] = []
    if not fits.converged:
        notes.append(f"likelihood fit: not converged in {cfg.max_iter} iterations")
    try:
        _check_noise(theta, objective, cfg)
        cov, factors = _covariance(objective, model, theta, cfg, y)
        _check(params, cov, L)
    except _FitError as exc:
        return Refinement(status="failed", reason=str(exc), params=None, theta=theta,
                          names=tuple(model.names), iterations=iterations, starts=fits.starts)
    noise = np.sqrt(np.exp(theta[4:6]) * fs)  # two-sided white PSD n -> std sqrt(n fs)
    return Refinement(
        status="ok", params=params, covariance=cov, theta=theta, names=tuple(model.names),
        neg_log_likelihood=float(best.fun), iterations=iterations, starts=fits.starts, band_hz=band,
        noise_std_mps2=(float(noise[0]), float(noise[1])),
        waviness=float(theta[model.index["waviness"]]) if cfg.estimate_waviness else 2.0,
        suspension_scale=tuple(np.exp(theta[-4:]).tolist()) if cfg.estimate_suspension else (),
        variance_factors=tuple(factors.tolist()), notes=tuple(notes),
    )


def _grid_starts(
    objective: WhittleObjective, spectra: Spectra, vehicle: Vehicle, noise_share: float
) -> list[np.ndarray]:
    """θ at the two best points of a coarse grid: body heave and pitch frequencies 0.8-1.8 Hz
    on the known static stiffness (eq 2-21), the CoG at 30-60 % of the wheelbase."""
    v = vehicle
    corners = ((v.suspension_stiffness_front_npm, v.tyre_stiffness_front_npm),
               (v.suspension_stiffness_rear_npm, v.tyre_stiffness_rear_npm))
    k = [ks * kt / (ks + kt) for ks, kt in corners]
    L = v.wheelbase_m
    scored = []
    for lf in (0.3 * L, 0.45 * L, 0.6 * L):
        for heave_hz in _GRID_HZ:
            for pitch_hz in _GRID_HZ:
                m = (k[0] + k[1]) / (2 * math.pi * heave_hz) ** 2
                inertia = (k[0] * lf**2 + k[1] * (L - lf) ** 2) / (2 * math.pi * pitch_hz) ** 2
                theta, S = _start(objective.model, spectra, np.array([m, inertia, lf]), noise_share)
                scored.append((objective.nll(S), len(scored), theta))
    scored = sorted(x for x in scored if math.isfinite(x[0]))
    if not scored:
        raise _FitError("likelihood fit: no grid point gave a finite likelihood")
    return [theta for _, _, theta in scored[:2]]


def _check_noise(theta: np.ndarray, objective: WhittleObjective, cfg: LikelihoodConfig) -> None:
    share = np.exp(theta[4:6]) / objective.band_power
    for name, value in zip(_CORNERS, share, strict=True):
        if value > cfg.max_noise_share:
            raise _FitError(
                f"likelihood fit explains the {name} channel as mostly noise ({value:.0%} of its power "
                f"in the band): a wrong basin or a faulty sensor"
            )


class _Fits:
    """Trust-region Newton fits from several starts; keeps the lowest ℓ."""

    def __init__(self, objective: WhittleObjective, cfg: LikelihoodConfig) -> None:
        self.objective, self.cfg = objective, cfg
        self.best: OptimizeResult | None = None
        self.iterations = self.starts = 0
        self.converged = False

    def run(self, theta0: np.ndarray) -> None:
        def stop_when_converged(intermediate_result: OptimizeResult) -> None:
            if self.objective.decrement(intermediate_result.x) < self.cfg.tol:
                raise StopIteration

        res = minimize(self.objective.fun, theta0, jac=self.objective.jac, hess=self.objective.hess,
                       method="trust-exact", callback=stop_when_converged,
                       options={"gtol": 1e-12, "maxiter": self.cfg.max_iter})
        self.iterations += int(res.nit)
        self.starts += 1
        if np.isfinite(res.fun) and (self.best is None or res.fun < self.best.fun):
            self.best = res
            self.converged = self.objective.decrement(res.x) < self.cfg.tol


def _agrees(params: np.ndarray, start: np.ndarray | None, start_std: np.ndarray | None) -> bool:
    """``params`` within 6 standard deviations of the start in every parameter."""
    if start is None or start_std is None or not np.all(np.isfinite(start_std)):
        return False
    return bool(np.all(np.abs(params - start) <= 6.0 * start_std))


def _band_power(spectra: Spectra) -> np.ndarray:
    """Mean PSD of each channel over the band [(m/s²)²/Hz]."""
    return np.einsum("kaa->a", spectra.periodogram).real / spectra.freq_hz.size


def _physical(params: np.ndarray, wheelbase_m: float) -> bool:
    """(m, I, lf) finite, positive and with the CoG between the axles."""
    p = np.asarray(params, dtype=float)
    return bool(p.shape == (3,) and np.all(np.isfinite(p)) and min(p[0], p[1]) > 0 and 0 < p[2] < wheelbase_m)


def _start_theta(
    model: HalfCarSpectrum, spectra: Spectra, params: np.ndarray, noise_share: float
) -> np.ndarray:
    """θ at ``params`` with the road intensity matched to the band's power."""
    return _start(model, spectra, params, noise_share)[0]


def _start(
    model: HalfCarSpectrum, spectra: Spectra, params: np.ndarray, noise_share: float
) -> tuple[np.ndarray, np.ndarray]:
    """(θ, S at θ) at ``params``, the road intensity matched to the band's power."""
    power = _band_power(spectra)
    theta = model.theta(params, 1.0, noise_share * power)
    S, _ = model.spectrum(theta, derivatives=False)
    floor = np.diag(noise_share * power + model.min_noise_psd)
    road = np.einsum("kaa->", S - floor).real / spectra.freq_hz.size
    scale = max(float(np.sum(power)) / road, 1e-300)
    theta[3] = math.log(scale)
    return theta, scale * (S - floor) + floor


def _covariance(objective: WhittleObjective, model: HalfCarSpectrum, theta: np.ndarray,
                cfg: LikelihoodConfig, accel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3, 3) covariance of (m, I, lf) from the information at the optimum, and the factors
    the time blocks applied to the model sandwich's variances.

    The score's variance along (m, I, lf) is the weighted mean of two estimates,
    ``(1 - ω) J_model + ω J_blocks`` (``ω = cfg.block_weight``), applied to the sandwich as
    a factor per parameter (``cov ← D cov D``, ``D = diag(√factor)``: the correlations stay).
    ``J_model`` is exact for a stationary Gaussian road and has no sampling noise; the
    blocks' (:func:`_block_variances`) is unbiased on any road, the non-stationary ones
    included, but with 8-10 blocks per window it has only 6-8 degrees of freedom.
    Used alone it would make the intervals Student-t-like (under-covering everywhere);
    ``ω = 1/2`` counts the model as much as the blocks: on stationary roads the published
    variance stays unbiased with half that noise, and a non-stationary road's excess is
    carried half way. A compromise by construction, not a fit to any seeds.
    """
    info = objective.observed_information(theta) if cfg.covariance == "observed" else objective.fisher(theta)
    # A noise floor far below its channel's power sits at its boundary (zero): the data
    # hold no information on it, so the fit is conditioned on it.
    keep = np.ones(theta.size, dtype=bool)
    keep[4:6] = np.exp(theta[4:6]) > _NOISE_AT_ZERO * objective.band_power
    if "ln_incoherence" in model.index:
        # Likewise the incoherent share when the data do not resolve it (noise dominates):
        # near its boundary the information's curvature misstates the other parameters'.
        k = model.index["ln_incoherence"]
        keep[k] = math.exp(theta[k]) > _INCOHERENCE_AT_ZERO
        if keep[k]:
            sub = info[np.ix_(keep, keep)]
            at = int(np.sum(keep[:k]))
            with np.errstate(all="ignore"):
                keep[k] = bool(np.linalg.pinv(sub)[at, at] < 1.0)  # std of ln(share) < 1
    info = info[np.ix_(keep, keep)]
    try:
        eig = np.linalg.eigvalsh(info)
        if not (np.all(np.isfinite(eig)) and eig.min() > 1e-12 * eig.max()):
            raise _FitError("likelihood fit: the information matrix is not positive definite")
        inv = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        raise _FitError("likelihood fit: singular information matrix") from None
    # Sandwich H⁻¹ J H⁻¹, projected on (m, I, lf) first: B = d(m, I, lf)/dθ H⁻¹.
    combos = np.zeros((3, theta.size))
    combos[:, keep] = model.physical_jacobian(theta)[:, keep] @ inv
    cov = objective.score_covariance(theta, combos)
    cov = 0.5 * (cov + cov.T)
    factors = np.ones(3)
    if cfg.block_weight > 0:
        blocks = _block_variances(objective, theta, combos, accel, cfg.block_s, cfg.taper)
        if blocks is not None and np.all(np.diag(cov) > 0):
            factors = 1.0 + cfg.block_weight * (blocks / np.diag(cov) - 1.0)
            scale = np.sqrt(factors)
            cov = scale[:, None] * cov * scale[None, :]
    return cov, factors


_MIN_BLOCKS = 6  # fewer time blocks than this: too few for a variance (the model's J alone)


def _block_variances(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray,
                     accel: np.ndarray, block_s: float, taper: float) -> np.ndarray | None:
    """Variances of ``combos ∇ℓ`` from the score's time blocks, or None (too few blocks).

    Why: the model's J assumes a stationary road. A road whose roughness changes along
    the way (the Laplace road: its intensity jumps every 100 m) makes the estimate vary
    more than that (conditionally on the road's envelope, and through the envelope's own
    smearing of the spectrum), and no stationary model can say by how much. The score
    itself can: ``Σ_k tr(A_k I_k)`` with ``A_k = S⁻¹ (combos ∂S) S⁻¹`` is a quadratic form of
    the (band-limited, tapered) samples, ``Σ_t ψ(t)`` with ``ψ(t) = ỹ_t · ẽ_t / (2 fs)``,
    ``ẽ`` the samples filtered by ``A`` (Parseval). Summed over time blocks ``G_b`` it is a
    sum of nearly independent terms whose spread estimates its variance whatever the
    road (batch means: robust to heteroscedastic, non-stationary data). For the efficient
    directions ``combos = d(m, I, lf)/dθ H⁻¹`` (road intensity and noise floors profiled
    out) a block's expectation is zero whatever its local road intensity:
    ``Σ_k tr(A_k S_road,k) = Σ_k tr(A_k N) = 0``.

    Three details make it work:

    - Blocks of ``block_s`` with raised-cosine edges as long as a block (a smooth
      partition of unity): ``ψ`` is local only beyond the filter's span; a sharp edge
      cuts through pairs of samples whose terms cancel only together (sharp 20 s blocks
      overstate the variance 3-10x).
    - The drift term: the response lags the road, so where the road's intensity ``a²``
      changes, ``ψ``'s local mean is ``c ∂a²/∂t`` (zero in total, but a block picks up
      ``c`` times the change of ``a²`` between its edges, far above its noise on a
      Laplace road). It is regressed out on ``D_b = -Σ_t v_b'(t) P(t)``, ``P`` the samples'
      local power (1 s moving average), and costs one degree of freedom.
    - The estimate at θ̂: the blocks' sum is zero (the fit's own score), which costs
      another degree of freedom: ``Var = B / (B - 2) Σ_b G_b²``.

    With ``B`` = 8-10 blocks (100-120 s windows) the estimate has only 6-8 degrees of
    freedom (±50-60 % on a variance): see :func:`_covariance` for how it is combined with
    the model's J. Blocks much shorter than ``block_s`` = 12 s overstate the variance even
    on Gaussian roads (the edges still cut the score's filter: 2x at 5 s, +10-40 % at
    10 s at 30-70 km/h); longer ones leave too few.
    """
    spectra = objective.spectra
    n, fs = spectra.n_samples, spectra.fs_hz
    n_blocks = int(n / fs // block_s)
    if spectra.dft is None or n_blocks < _MIN_BLOCKS or accel.shape[0] != n:
        return None
    psi = _score_series(objective, theta, combos)
    weights = _partition(n, n_blocks)
    w2 = windows.tukey(n, taper) ** 2 if taper > 0 else np.ones(n)
    share = weights @ (w2 / w2.sum())  # each block's share of the score's expectation
    G = weights @ psi.T  # (B, 3)
    G -= share[:, None] * G.sum(axis=0)
    y = accel - accel.mean(axis=0)
    power = _moving_average(np.einsum("ta,ta->t", y, y), max(1, round(fs)))
    drift = -(np.gradient(weights, axis=1) @ power)
    drift -= share * drift.sum()
    dof = n_blocks - 1
    if drift @ drift > 0:
        G -= np.outer(drift, (drift @ G) / (drift @ drift))
        dof -= 1
    return n_blocks / dof * np.einsum("bq,bq->q", G, G)


def _score_series(objective: WhittleObjective, theta: np.ndarray, combos: np.ndarray) -> np.ndarray:
    """(q, n) ψ(t): the score's data term ``Σ_k tr(A_k I_k)`` along each of ``combos`` as a
    sum over the samples, ``A_k = S⁻¹ (combos ∂S) S⁻¹`` (restricted as the fit's).

    ``ψ(t) = ỹ_t · ẽ_t / (2 fs)`` with ``ỹ`` the tapered samples and ``ẽ`` the samples filtered
    by ``A``, both band-limited (inverse FFTs of ``d_k`` and ``A_k d_k`` on the band): by
    Parseval ``Σ_t ψ(t) = Re Σ_k d_kᴴ A_k d_k / (n fs)``.
    """
    spectra = objective.spectra
    n, fs, d = spectra.n_samples, spectra.fs_hz, spectra.dft
    S, dS = objective.model.spectrum(theta)
    S, dS = objective._restrict(S), objective._restrict(dS)
    inv = _inv2(S)[0]
    A = inv[None] @ np.tensordot(combos, dS, axes=1) @ inv[None]  # (q, k, 2, 2)
    k0, k = spectra.first_bin, d.shape[0]
    full = np.zeros((1 + combos.shape[0], n // 2 + 1, 2), dtype=complex)  # ỹ and the filtered ẽ
    full[0, k0: k0 + k] = d
    full[1:, k0: k0 + k] = np.einsum("qkab,kb->qka", A, d)
    series = sfft.irfft(full, n=n, axis=1)
    return np.einsum("ta,qta->qt", series[0], series[1:]) / (2.0 * fs)


def _partition(n: int, n_blocks: int) -> np.ndarray:
    """(B, n) a smooth partition of unity: B blocks, each rising and falling over a block's
    length with raised cosines (each sample shared by at most two neighbouring blocks)."""
    length = n / n_blocks
    t = (np.arange(n) + 0.5) / length - 0.5  # block centres at 0, 1, ..
    out = np.zeros((n_blocks, n))
    for b in range(n_blocks):
        x = np.clip(t - b, -1.0, 1.0)
        v = np.cos(0.5 * np.pi * x) ** 2
        if b == 0:
            v[t < 0] = 1.0
        if b == n_blocks - 1:
            v[t > n_blocks - 1] = 1.0
        out[b] = v
    return out / out.sum(axis=0)


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average over ``width`` samples (shorter at the ends)."""
    c = np.r_[0.0, np.cumsum(x)]
    lo = np.clip(np.arange(x.size) - width // 2, 0, x.size)
    hi = np.clip(lo + width, 0, x.size)
    return (c[hi] - c[lo]) / (hi - lo)


def _check(params: np.ndarray, cov: np.ndarray, L: float) -> None:
    if not np.all(np.isfinite(params)) or not np.all(np.isfinite(cov)):
        raise _FitError("likelihood fit: not finite")
    if not 1e-3 * L < params[2] < (1 - 1e-3) * L:
        raise _FitError(f"likelihood fit: CoG at the wheelbase's end (lf = {params[2]:.4g} m)")
