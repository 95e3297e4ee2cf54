"""The half car's spectral model: :class:`HalfCarSpectrum` (the 2x2 spectral matrix of the
front/rear accelerations on a frequency grid, its parameters θ and its derivatives dS/dθ).

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

``R = [[1, φ̄], [φ, 1]]``, ``φ = e^(-iωτ)`` at constant speed (rank one; a varying drive's
mixture: :func:`road_mixture`), ``r = |f / f_ref|^(2-w) exp(Σ c_d P_d(x))`` the road's shape
(ISO 8608's power law times Legendre departures in log frequency ``x``), the sum over
``a = -A..A`` the aliasing of sampling (of the road below its profile's end only:
:func:`spatial_band`), ``n_f, n_r`` white sensor noise. Optionally a share ``ε`` of the road
part's diagonal is incoherent between the channels (a model-error floor, for nearly noise-free
data).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal, overload

import numpy as np
from scipy import special

from rozyn_estimator.gravity import gravity_height_m, rotation_inertia_kgm2, rotation_stiffness_nmprad
from rozyn_estimator.method.likelihood import corners as cn
from rozyn_estimator.method.likelihood.grid import (
    Reduction,
    diagonal_part,
    evaluation_grid,
    hermitian_part,
    interpolation,
    map_bins,
    reduction,
)
from rozyn_estimator.method.likelihood.road_input import (
    delay_characteristic,
    is_varying,
    road_mixture,
    spatial_band,
)
from rozyn_estimator.vehicle import Vehicle

# Corner values θ can hold as log scale factors (``ln_<term>_<corner>``), in θ's order:
# the suspension's stiffness and damping, the tyre's, the unsprung mass.
CORNERS = cn.CORNERS  # front, rear
CORNER_TERMS = ("stiffness", "damping", "tyre_stiffness", "tyre_damping", "unsprung_mass")
_INCOHERENCE_START = 1e-4


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
        corner_terms: further corner values θ holds as log scale factors (of
            :data:`CORNER_TERMS`; ``estimate_suspension`` adds the first two).
        sensor_positions: θ also holds the sensors' positions as departures from the
            vehicle's (``sensor_front_x_m``, ``sensor_rear_x_m``, metres).
        calibrate_gain, calibrate_time_offset: θ also holds the rear sensor's gain relative
            to the front one (``ln_rear_gain``) and its delay behind the front one
            (``time_offset_ms``): the sensors' self-calibration.
        shape_edges_hz: the band the road shape's polynomials span (default: the grid's).
        min_noise_psd: (front, rear) white floor added to the fitted noise [(m/s²)²/Hz]:
            keeps S positive definite when the data are noise-free.
        grid_step: the model is evaluated every ``grid_step`` bins and interpolated
            (:mod:`.grid`; the taper's smoothing is applied there too).
        road_max_cpm: the road's profile ends at this spatial frequency [cycles/m]: the
            aliases hold the road below it only (:func:`.road_input.spatial_band`); 0: no end.
        sample_weights: with a speed per sample, what each counts for in the periodogram (the
            taper's square; None: alike): the wheelbase delays' mixture is weighted by it.
    """

    def __init__(
        self, vehicle: Vehicle, freq_hz: np.ndarray, fs_hz: float, speed_mps: float | np.ndarray,
        aliases: int = 1, f_ref_hz: float = 3.0, estimate_waviness: bool = False,
        estimate_suspension: bool = False, min_noise_psd: tuple[float, float] = (0.0, 0.0),
        road_shape_terms: int = 0, estimate_incoherence: bool = False,
        window_weights: np.ndarray | None = None, calibrate_gain: bool = False,
        calibrate_time_offset: bool = False, shape_edges_hz: tuple[float, float] | None = None,
        corner_terms: tuple[str, ...] = (), sensor_positions: bool = False, grid_step: int = 1,
        road_max_cpm: float = 0.0, sample_weights: np.ndarray | None = None,
    ) -> None:
        self.freq_hz, self.fs_hz, self.aliases, self.f_ref_hz = freq_hz, fs_hz, aliases, f_ref_hz
        self._settings: dict[str, Any] = dict(  # what variant() rebuilds the model from
            vehicle=vehicle, freq_hz=freq_hz, fs_hz=fs_hz, speed_mps=speed_mps, aliases=aliases,
            f_ref_hz=f_ref_hz, estimate_waviness=estimate_waviness, estimate_suspension=estimate_suspension,
            min_noise_psd=min_noise_psd, road_shape_terms=road_shape_terms,
            estimate_incoherence=estimate_incoherence, window_weights=window_weights,
            calibrate_gain=calibrate_gain, calibrate_time_offset=calibrate_time_offset,
            shape_edges_hz=shape_edges_hz, corner_terms=corner_terms, sensor_positions=sensor_positions,
            grid_step=grid_step, road_max_cpm=road_max_cpm, sample_weights=sample_weights,
        )
        # the grid the model is evaluated on (cached: consecutive windows and the model's variants share it)
        at = evaluation_grid(freq_hz, fs_hz, aliases, f_ref_hz, window_weights, grid_step, road_shape_terms,
                             shape_edges_hz)
        self.kernel, self.half, self.n_eval = at.kernel, at.half, at.n_eval
        self.n_ext, self.n_freq, self.n_alias = freq_hz.size + 2 * self.half, freq_hz.size, 2 * aliases + 1
        self.omega, self.log_shape, self.shape_basis = at.omega, at.log_shape, at.shape_basis
        aliased = np.repeat(np.arange(-aliases, aliases + 1) != 0, self.n_eval)
        self.varying, self.road_max_cpm = is_varying(speed_mps), road_max_cpm
        band = spatial_band(self.omega / (2.0 * np.pi), speed_mps, road_max_cpm)
        # the band keeps its road (S stays smooth); a varying drive's mixture carries the road's end
        self.alias_road = np.where(aliased & (not self.varying), band, 1.0)
        self.grid_step = grid_step
        self._reduction: Reduction | None = None  # the sparse map to the bins: built when first used
        self.speed_mps, self.sample_weights = speed_mps, sample_weights
        self.rear_factor: np.ndarray | None = None  # assumed rear gain and delay (None: ideal)
        self.set_vehicle(vehicle)
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
        wanted = set(corner_terms) | ({"stiffness", "damping"} if estimate_suspension else set())
        self.corner_terms = tuple(q for q in CORNER_TERMS if q in wanted)
        first_corner = len(self.names)
        self.names += [f"ln_{q}_{c}" for q in self.corner_terms for c in cn.CORNERS]
        self.corner_slice = slice(first_corner, len(self.names))
        if sensor_positions:
            self.names += ["sensor_front_x_m", "sensor_rear_x_m"]
        if calibrate_gain:
            self.names.append("ln_rear_gain")
        if calibrate_time_offset:
            self.names.append("time_offset_ms")
        self.n_params = len(self.names)
        self.index = {name: k for k, name in enumerate(self.names)}

    def variant(self, **changes: Any) -> HalfCarSpectrum:
        """The same model with some of its construction arguments changed (e.g. more
        nuisance parameters, another frequency grid)."""
        return HalfCarSpectrum(**(self._settings | changes))

    def set_vehicle(self, vehicle: Vehicle, rear_gain: float = 1.0, time_offset_s: float = 0.0) -> None:
        """(Re)compute what depends on the assumed vehicle and sensors: the corners, the
        sensor positions, the wheelbase delay; ``rear_gain`` and ``time_offset_s`` are the
        rear sensor's assumed gain relative to the front one and its delay behind it.
        (The budget perturbs these one at a time.)"""
        v = vehicle
        self.vehicle = v
        self.wheelbase_m = L = v.wheelbase_m
        w = self.omega
        # Front/rear road velocity covariance R = [[W, φ̄], [φ, W]] = C Cᴴ, C lower triangular;
        # at constant speed W = |φ| = 1 and the second column vanishes.
        share, phi = road_mixture(w, L, np.asarray(self.speed_mps), self.sample_weights, self.road_max_cpm,
                                  self.fs_hz) if self.varying else (np.ones(w.shape), delay_characteristic(
                                      w, L, self.speed_mps))
        root = np.sqrt(share)
        self.inputs = [np.array([root, np.divide(phi, root, out=np.zeros_like(phi), where=root > 0)])]
        spread = share - np.abs(self.inputs[0][1]) ** 2
        if np.max(spread) > 1e-12:
            self.inputs.append(np.array([np.zeros_like(phi), np.sqrt(np.maximum(spread, 0.0))]))
        self.pitch_gyro = v.pitch_gyro  # the second channel reads -φ' (gyro_y), not an acceleration
        self.sensor_map = cn.sensor_map(np.asarray(v.sensor_x_m), L, self.pitch_gyro)
        self.ks0 = np.array([v.suspension_stiffness_front_npm, v.suspension_stiffness_rear_npm])
        self.cs0 = np.array([v.suspension_damping_front_nspm, v.suspension_damping_rear_nspm])
        self.kt0 = np.array([v.tyre_stiffness_front_npm, v.tyre_stiffness_rear_npm])
        self.ct0 = np.array([v.tyre_damping_front_nspm, v.tyre_damping_rear_nspm])
        self.mt0 = np.array([v.unsprung_mass_front_kg, v.unsprung_mass_rear_kg])
        self.gravity_height_m = gravity_height_m(v)
        self.unsprung_total_kg = float(self.mt0.sum())
        self.z_tyre = self.kt0 + 1j * w[:, None] * self.ct0  # (A k, 2)
        self.w_tyre = self.z_tyre - (w * w)[:, None] * self.mt0  # tyre minus wheel inertia
        ideal = rear_gain == 1.0 and time_offset_s == 0.0
        self.rear_factor = None if ideal else rear_gain * np.exp(-1j * w * time_offset_s)
        if self.pitch_gyro:  # the gyro's row reads a rate: a factor on it (corners.gyro_factor)
            self.rear_factor = cn.gyro_factor(w) * (1.0 if self.rear_factor is None else self.rear_factor)

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
        th += [0.0] * (self.n_params - len(th))  # suspension scales, sensor gain and offset: nominal
        return np.array(th)

    def physical(self, theta: np.ndarray) -> np.ndarray:
        """(m [kg], I [kg m²], lf [m]) from θ."""
        with np.errstate(over="ignore"):  # inf outside the domain (see :meth:`spectrum`)
            return np.array([*np.exp(theta[:2]), special.expit(theta[2]) * self.wheelbase_m])

    def physical_jacobian(self, theta: np.ndarray) -> np.ndarray:
        """(3, n_params) d(m, I, lf)/dθ."""
        m, inertia, lf = self.physical(theta)
        p = lf / self.wheelbase_m
        jac = np.zeros((3, self.n_params))
        jac[0, 0], jac[1, 1], jac[2, 2] = m, inertia, self.wheelbase_m * p * (1.0 - p)
        return jac

    def _mass_matrix(self, theta: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
        """M_ax (2, 2), its derivatives by (ln m, ln I, logit lf/L), and the weight's pitch
        stiffness through the geometry in the axle coordinates (``-m g h`` on the pitch
        ``(x_sf - x_sr)/L``, :mod:`rozyn_estimator.gravity`: also its derivative by ln m); its
        inertia ``μ h²`` adds to I."""
        m, inertia, lf = self.physical(theta)
        L = self.wheelbase_m
        lr = L - lf
        heave = np.array([[lr * lr, lf * lr], [lf * lr, lf * lf]]) / L**2
        pitch = np.array([[1.0, -1.0], [-1.0, 1.0]]) / L**2
        d_lf = np.array([[-2.0 * lr, lr - lf], [lr - lf, 2.0 * lf]]) / L**2
        p = lf / L
        swing, d_swing = rotation_inertia_kgm2(m, self.gravity_height_m, self.unsprung_total_kg)
        mass = m * heave + (inertia + swing) * pitch
        d_mass = [m * heave + d_swing * pitch, inertia * pitch, m * d_lf * L * p * (1.0 - p)]
        return mass, d_mass, rotation_stiffness_nmprad(m, self.gravity_height_m) * pitch

    # --- the model ----------------------------------------------------------------------
    @overload
    def spectrum(
        self, theta: np.ndarray, derivatives: Literal[True] = ..., smooth: Literal[True] = ...,
        rows: Sequence[str] | None = ...,
    ) -> tuple[np.ndarray, np.ndarray]: ...

    @overload
    def spectrum(
        self, theta: np.ndarray, derivatives: bool = ..., smooth: bool = ..., rows: Sequence[str] | None = ...
    ) -> tuple[np.ndarray, np.ndarray | None]: ...

    def spectrum(
        self, theta: np.ndarray, derivatives: bool = True, smooth: bool = True,
        rows: Sequence[str] | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """S (k, 2, 2) and, if asked, dS/dθ (n_params, k, 2, 2) (None when not asked); with
        ``rows`` only the derivatives by those parameters, in that order.

        ``smooth=False``: S and dS at the evaluation grid's nodes (``reduction.bins`` takes
        them to the bins). Where θ is so far from any vehicle that a value overflows, S and
        dS are NaN: every likelihood reads that as impossible (the one guard for optimiser
        steps, warm starts and calibration steps that wander off).
        """
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            S, dS = self._spectrum(theta, derivatives, smooth, rows)
        if not (np.all(np.isfinite(S)) and (dS is None or np.all(np.isfinite(dS)))):
            S = np.full_like(S, np.nan)
            dS = None if dS is None else np.full_like(dS, np.nan)
        return S, dS

    def _spectrum(
        self, theta: np.ndarray, derivatives: bool, smooth: bool, rows: Sequence[str] | None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`spectrum`'s work.

        With ``R = C Cᴴ`` (``C`` the columns of :attr:`inputs`), ``G R Gᴴ = Σ_c g_c g_cᴴ``
        with ``g_c = iω P x_c``, ``x_c = H (T ⊙ C_c)``, ``H = (diag Z - ω² M_ax)⁻¹``: every
        quantity is a 2-vector per frequency, and a derivative of ``H`` needs no solve
        (``∂x = -H ∂D x + H (∂T ⊙ C_c)``).
        """
        w = self.omega
        w2 = w * w
        scale = dict(zip(self.corner_terms, np.exp(theta[self.corner_slice]).reshape(-1, 2), strict=True))
        ks = self.ks0 * scale["stiffness"] if "stiffness" in scale else self.ks0
        cs = self.cs0 * scale["damping"] if "damping" in scale else self.cs0
        zt, wt = self.z_tyre, self.w_tyre
        kt, ct, mt = self.kt0, self.ct0, self.mt0
        if {"tyre_stiffness", "tyre_damping", "unsprung_mass"} & set(scale):
            kt = self.kt0 * scale.get("tyre_stiffness", 1.0)
            ct = self.ct0 * scale.get("tyre_damping", 1.0)
            mt = self.mt0 * scale.get("unsprung_mass", 1.0)
            zt = kt + 1j * w[:, None] * ct
            wt = zt - w2[:, None] * mt
        zs = ks + 1j * w[:, None] * cs  # (F, 2) suspension
        den = zs + wt
        Z = zs * wt / den  # condensed corner stiffness
        T = zs * zt / den  # road height -> force on the body
        mass, d_mass, geo = self._mass_matrix(theta)
        d11 = Z[:, 0] + geo[0, 0] - w2 * mass[0, 0]  # D = diag(Z) + K_g - ω² M_ax (complex symmetric)
        d22 = Z[:, 1] + geo[1, 1] - w2 * mass[1, 1]
        d12 = geo[0, 1] - w2 * mass[0, 1]
        det = d11 * d22 - d12 * d12
        H = np.array([[d22, -d12], [-d12, d11]]) / det  # (2, 2, F)
        P = self.sensor_map
        if "sensor_front_x_m" in self.index:  # the sensors moved by θ's departures
            k = self.index["sensor_front_x_m"]
            x_s = np.asarray(self.vehicle.sensor_x_m) + theta[k: k + 2]
            P = cn.sensor_map(x_s, self.wheelbase_m, self.pitch_gyro)
        iw = 1j * w
        Q = iw * np.einsum("ab,bcf->acf", P, H)  # iω P H
        exponent = ((2.0 - theta[self.index["waviness"]]) if self.estimate_waviness else 0.0) * self.log_shape
        weight = self.alias_road * np.exp(theta[3] + exponent + theta[self.shape_slice] @ self.shape_basis)
        u = [T.T * c for c in self.inputs]  # T ⊙ C_c, each (2, F)
        x = [np.einsum("abf,bf->af", H, uc) for uc in u]
        g = [iw * (P @ xc) for xc in x]
        rear = self._rear_factor(theta)
        if rear is not None:  # the rear sensor's gain and delay: a factor on its row of P
            Q = Q.copy()
            Q[1] *= rear
            for gc in g:
                gc[1] *= rear
        gg = sum(np.einsum("af,bf->fab", gc, gc.conj()) for gc in g)  # Σ_c g_c g_cᴴ, (F, 2, 2)
        rank = self._fold(gg, weight)
        if smooth:
            rank = self.reduction.bins(rank)
        k_inc = self.index.get("ln_incoherence")
        incoherence = np.exp(theta[k_inc]) if k_inc is not None else 0.0
        S_road = rank + incoherence * diagonal_part(rank) if k_inc is not None else rank
        noise = np.exp(theta[4:6])
        S = S_road.copy()
        S[:, 0, 0] += noise[0] + self.min_noise_psd[0]
        S[:, 1, 1] += noise[1] + self.min_noise_psd[1]
        if not derivatives:
            return S, None
        want = set(self.names if rows is None else rows)
        road: dict[str, np.ndarray] = {}  # ∂(rank part) on the extended grid, in θ's order
        for j, name in enumerate(self.names[:3]):  # ∂D = ∂K_g - ω² dM: ∂g = Q (ω² dM - ∂K_g) x
            if name in want:
                dg = [w2 * np.einsum("abf,bf->af", Q, d_mass[j] @ xc) for xc in x]
                if j == 0 and self.gravity_height_m != 0.0:  # K_g is linear in m
                    dg = [d - np.einsum("abf,bf->af", Q, geo @ xc) for d, xc in zip(dg, x, strict=True)]
                road[name] = hermitian_part(self._outer_sum(dg, g, weight))
        if self.estimate_waviness and "waviness" in want:
            road["waviness"] = self._fold(gg, -weight * self.log_shape)
        for name, basis in zip(self.names[self.shape_slice], self.shape_basis, strict=True):
            if name in want:
                road[name] = self._fold(gg, weight * basis)
        corner_rows = [(q, k) for q in self.corner_terms for k in range(2)
                       if f"ln_{q}_{cn.CORNERS[k]}" in want]
        if corner_rows:  # the corner values' rows, as one stack (likelihood/corners.py)
            state = cn.CornerState(ks, cs, kt, ct, mt, zs, zt, wt, den)
            outer = cn.corner_outer(state, corner_rows, w, Q, np.stack(self.inputs), np.stack(x), np.stack(g))
            stacked = hermitian_part(self._fold(outer, weight))
            road |= {f"ln_{q}_{cn.CORNERS[k]}": m for (q, k), m in zip(corner_rows, stacked, strict=True)}
        for name, dg in cn.sensor_dg(self, want, x, g, iw, rear).items():
            road[name] = hermitian_part(self._outer_sum(dg, g, weight))
        out = list(self.names) if rows is None else list(rows)
        at = {name: i for i, name in enumerate(out)}
        dS = np.zeros((len(out), self.n_freq if smooth else self.n_eval, 2, 2), dtype=complex)
        if road:
            smoothed = np.stack(list(road.values()))
            smoothed = self.reduction.bins(smoothed) if smooth else smoothed
            dS[[at[name] for name in road]] = (smoothed + incoherence * diagonal_part(smoothed)
                                               if k_inc is not None else smoothed)
        special = {"ln_road": S_road}
        if k_inc is not None:
            special["ln_incoherence"] = incoherence * diagonal_part(rank)
        for name, value in special.items():
            if name in at:
                dS[at[name]] = value
        if "ln_noise_front" in at:
            dS[at["ln_noise_front"], :, 0, 0] = noise[0]
        if "ln_noise_rear" in at:
            dS[at["ln_noise_rear"], :, 1, 1] = noise[1]
        return S, dS

    def _rear_factor(self, theta: np.ndarray) -> np.ndarray | None:
        """The rear sensor's gain and delay as a factor per frequency (None: ideal)."""
        factor = self.rear_factor
        if "ln_rear_gain" in self.index:
            gain = np.exp(theta[self.index["ln_rear_gain"]])
            factor = np.full(self.omega.shape, gain) if factor is None else factor * gain
        if "time_offset_ms" in self.index:
            delay = np.exp(-1e-3j * self.omega * theta[self.index["time_offset_ms"]])
            factor = delay if factor is None else factor * delay
        return None if factor is None else np.broadcast_to(factor, self.omega.shape)

    @property
    def reduction(self) -> Reduction:
        """The sparse map from the evaluation grid to the bins (:mod:`.grid`)."""
        if self._reduction is None:
            self._reduction = reduction(self.n_freq, self.kernel, self.grid_step)
        return self._reduction

    def fine_spectrum(self, theta: np.ndarray) -> np.ndarray:
        """S at every bin of the extended grid (k + 2J, 2, 2), unsmoothed: interpolated from
        the evaluation grid's nodes (within 1e-4 of S; nearly noise-free data, where S is
        nearly singular and that error could matter, are fitted with a node at every bin)."""
        S = self.spectrum(theta, derivatives=False, smooth=False)[0]
        return S if self.grid_step == 1 else map_bins(interpolation(self.n_ext, self.grid_step), S)

    def _outer_sum(self, a: list[np.ndarray], b: list[np.ndarray], weight: np.ndarray) -> np.ndarray:
        """Σ_c weight a_c b_cᴴ folded over the aliases: (n_eval, 2, 2) on the evaluation grid."""
        out = sum(np.einsum("af,bf->fab", ac, bc.conj()) for ac, bc in zip(a, b, strict=True))
        return self._fold(out, weight)

    def _fold(self, m: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """(..., F, 2, 2) on the aliased grid, weighted, summed over the aliases: (..., n_eval, 2, 2)."""
        out = m * weight[:, None, None]
        return out.reshape(*m.shape[:-3], self.n_alias, self.n_eval, 2, 2).sum(axis=-4)

