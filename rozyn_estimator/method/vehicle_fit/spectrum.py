"""The vehicle's spectral model: :class:`VehicleSpectrum` (the k×k spectral matrix of the body's
channels driven by the road, its parameters θ and dS/dθ), for the full car and the half car (its
two corners on the centreline, one track, no roll: ``q = (z₀, φ)``). Each corner is its
suspension (with the anti-roll bars: :func:`~.corner_matrices.corner_matrices`)
on its wheel on its tyre; condensing the wheels exactly, the corners push on the body with
``F = -Z(ω) x_c + T(ω) u`` (4×4 each, known). The body's coordinates are taken
at the front axle's centre, ``q = (z₀, φ, θ)``: a point ``(x, y)`` moves
``z₀ - x φ + y θ`` (``B`` for the corners, ``P`` for the sensors), the centre of gravity ``t·q``
with ``t = (1, -l_f, y_c)``: ``M = m t tᵀ + diag(0, I_yy, I_xx)`` (the inertias enter only there).
Per unit road velocity at the four wheels the accelerations are

    G(ω) = iω P D⁻¹ Bᵀ T(ω),   D = Bᵀ Z(ω) B - ω² M,

and the sampled signals' spectral matrix is ``S(f) = σ² Σ_a r(f_a) G(ω_a) R(ω_a) G(ω_a)ᴴ + diag(n)``
with the road's shape ``r`` (ISO 8608's power law times Legendre departures in log frequency)
and aliasing sum (:func:`spatial_band`), a white noise floor per sensor, and the wheels' road
velocity covariance ``R = [[W Γ, Γ φ̄], [Γ φ, W Γ]]`` (front wheels, then rear, each left and
right; the half car's one track: ``R = [[W, φ̄], [φ, W]]``): ``φ`` the rear wheels' delay behind the front
ones in their tracks (``W = 1``; a varying drive's mixture: :func:`road_mixture`), ``Γ = [[1,
γ], [γ, 1]]`` the tracks' coherence: the isotropic surface's (Dodds & Robson 1973; Kamash &
Robson 1978) for ``w = 2``, ``γ = x K₁(x)``, ``x = 2π n B e^c`` at ``n = f / v``, ``B`` the
front track, ``c`` a fitted log scale of the tracks' separation (its one nuisance).
"""

from __future__ import annotations

import contextlib
import copy
import math
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
from numpy.polynomial import legendre
from scipy import sparse

from rozyn_estimator.body_model import AnyVehicle, channel_rows
from rozyn_estimator.gravity import gravity_height_m
from rozyn_estimator.method.body_parameters import BodyParameters
from rozyn_estimator.method.likelihood.road_input import (
    delay_characteristic,
    driving_speed,
    is_varying,
    spatial_band,
    track_coherence,
    track_mixture,
)
from rozyn_estimator.method.vehicle_fit.corner_matrices import corner_matrices, corner_response_derivatives
from rozyn_estimator.method.vehicle_fit.grid import ALIAS_SPACING_HZ, alias_map, apply, evaluation_map
from rozyn_estimator.method.vehicle_fit.stacks import herm, mul
from rozyn_estimator.method.vehicle_fit.uncertainty import sensing as sensor_model


class VehicleSpectrum:
    """The vehicle's spectral matrix and its derivatives on the band's Fourier frequencies.

    Args:
        vehicle: the known corners, bars, geometry and sensor positions (either car).
        sensors: the vehicle's channel (its ``channel_kinds`` index) of each column.
        freq_hz: (K,) the frequencies [Hz].
        fs_hz: sample rate [Hz] (for the aliasing terms).
        speed_mps: the speed, constant or per sample [m/s]; per sample, ``sample_weights`` are
            what each counts for (the taper's square: :func:`road_mixture`).
        aliases: aliasing terms ``a = -A..A``.
        f_ref_hz: the road shape's reference frequency.
        road_shape_terms: smooth departures of the road spectrum from a power law.
        min_noise_psd: (k,) a white floor added to each channel's fitted noise [(m/s²)²/Hz].
        shape_edges_hz: the band the road shape's polynomials span (default: the grid's).
        kernel_m2_hz2: (K,) or a number: the second moment [Hz²] of the kernel that makes each
            periodogram ordinate a local average of S (the taper's spectral window, a group's
            spread of bins; :func:`expected_periodogram_m2`); 0: the model is S itself.
        grid_hz: S is evaluated this far apart and interpolated (:mod:`.grid`); 0: at each.
        road_max_cpm: the road's profile ends at this spatial frequency [cycles/m]: the
            aliases hold the road below it only (:func:`spatial_band`); 0: no end.
        calibrate: the sensors' values θ also holds (:data:`.sensing.GROUPS`: ``gain``, ``x``,
            ``y``, ``delay``, ``turn``; after the noise floors, as :func:`.sensing.parameter_names`).
        sensor_values: the sensors' departures from the vehicle's the model assumes (all of
            :func:`.sensing.parameter_names`' values for every group; None: none).
    """

    def __init__(self, vehicle: AnyVehicle, sensors: Sequence[int], freq_hz: np.ndarray, fs_hz: float,
                 speed_mps: float | np.ndarray, aliases: int = 1, f_ref_hz: float = 3.0,
                 road_shape_terms: int = 2, min_noise_psd: np.ndarray | None = None,
                 shape_edges_hz: tuple[float, float] | None = None,
                 kernel_m2_hz2: np.ndarray | float = 0.0, grid_hz: float = 0.0,
                 road_max_cpm: float = 0.0, calibrate: Sequence[str] = (),
                 sensor_values: np.ndarray | None = None, sample_weights: np.ndarray | None = None) -> None:
        self.freq_hz = freq_hz
        edges_hz = shape_edges_hz or (float(freq_hz.min()), float(freq_hz.max()))
        m2 = np.broadcast_to(np.asarray(kernel_m2_hz2, dtype=float), freq_hz.shape)
        self._settings: dict[str, Any] = dict(  # what regrid() rebuilds the model from
            vehicle=vehicle, sensors=sensors, fs_hz=fs_hz, speed_mps=speed_mps, aliases=aliases,
            f_ref_hz=f_ref_hz, road_shape_terms=road_shape_terms, min_noise_psd=min_noise_psd,
            shape_edges_hz=edges_hz, kernel_m2_hz2=m2, grid_hz=grid_hz, road_max_cpm=road_max_cpm,
            calibrate=tuple(calibrate), sensor_values=sensor_values, sample_weights=sample_weights)
        self.sensors, self.k = tuple(sensors), len(sensors)
        self.layout = sensor_model.channel_layout([vehicle.channel_late[c] for c in self.sensors],
                                                  [vehicle.channel_kinds[c] for c in self.sensors])
        self.calibrate = tuple(g for g in sensor_model.GROUPS if g in calibrate)
        self.sensor_values = None if sensor_values is None else \
            sensor_model.unpack(np.asarray(sensor_values, dtype=float), sensor_model.GROUPS, self.k)
        nodes, self._op = evaluation_map(freq_hz, m2, grid_hz)  # where S is evaluated, the map from there
        self._op_t = None if self._op is None else sparse.csr_array(self._op.T)
        self._row_ops: dict[bytes, sparse.csr_array] = {}  # the map's rows at some frequencies
        self.grid_hz = grid_hz if self._op is not None and nodes.size < self.freq_hz.size else 0.0
        alias_nodes, self._alias_fold = alias_map(nodes, ALIAS_SPACING_HZ if grid_hz > 0 else 0.0)
        shifts = np.array([a for a in range(-aliases, aliases + 1) if a != 0], dtype=float) * fs_hz
        self.n_freq, self.n_alias_terms, self.n_alias_nodes = nodes.size, shifts.size, alias_nodes.size
        f = np.r_[nodes, (alias_nodes[None, :] + shifts[:, None]).ravel()]  # the band's nodes, then aliases'
        self.omega = 2.0 * np.pi * f
        self.speed_mps, self.sample_weights, self.road_max_cpm = speed_mps, sample_weights, road_max_cpm
        self.fs_hz = fs_hz
        self.varying = is_varying(speed_mps)  # a varying drive's mixture carries the road's end
        self.alias_road = np.r_[np.ones(nodes.size), np.ones(f.size - nodes.size) if self.varying else
                                spatial_band(f[nodes.size:], speed_mps, road_max_cpm)]
        self.log_shape = np.log(np.abs(f) / f_ref_hz)
        edges = np.log(np.array(edges_hz) / f_ref_hz)
        x = (2.0 * self.log_shape - edges.sum()) / (edges[1] - edges[0])
        x[nodes.size:] = np.clip(x[nodes.size:], -1.0, 1.0)  # the band's continue smoothly just beyond it
        self.shape_basis = np.array([legendre.legval(x, np.eye(road_shape_terms + 2)[d])
                                     for d in range(2, road_shape_terms + 2)]).reshape(road_shape_terms, -1)
        self.min_noise_psd = np.zeros(self.k) if min_noise_psd is None else np.asarray(min_noise_psd, float)
        self.rolls = vehicle.ROLLS  # two tracks and the body's roll, or the half car's one track
        self.wheelbase_m = vehicle.wheelbase_m  # l_f's scale in θ: kept when the budget moves the vehicle
        self.body = BodyParameters(self.wheelbase_m, self.rolls)
        self.n_body = nb = self.body.size
        shapes = [f"road_shape_{d}" for d in range(2, road_shape_terms + 2)]
        self.names = [*self.body.names, "ln_road", "waviness", *shapes, *(["ln_coherence_scale"] if self.rolls
                                                                          else []),
                      *[f"ln_noise_{i}" for i in range(self.k)]]
        self.noise_slice = slice(len(self.names) - self.k, len(self.names))
        self.names += sensor_model.parameter_names(self.calibrate, self.k)
        self.calibration_slice = slice(self.noise_slice.stop, len(self.names))
        self.index = {name: i for i, name in enumerate(self.names)}
        self.n_params = len(self.names)
        self.road_index, self.waviness_index = nb, nb + 1
        self.shape_slice = slice(nb + 2, nb + 2 + road_shape_terms)
        self._body_key: bytes | None = None  # body_motion's cache
        self._body_value: tuple[np.ndarray, ...] | None = None
        self.set_vehicle(vehicle)

    @property
    def settings(self) -> dict[str, Any]:  # the construction arguments but the frequencies (a copy)
        return dict(self._settings)

    def regrid(self, freq_hz: np.ndarray, kernel_m2_hz2: np.ndarray | float,
               grid_hz: float) -> VehicleSpectrum:
        """The same model (the same θ) at other frequencies (``grid_hz`` 0: S at each)."""
        m2 = np.broadcast_to(np.asarray(kernel_m2_hz2, dtype=float), freq_hz.shape)
        changes = {"vehicle": self.vehicle, "kernel_m2_hz2": m2, "grid_hz": grid_hz}
        return VehicleSpectrum(freq_hz=freq_hz, **(self._settings | changes))

    def calibrating(self, groups: Sequence[str]) -> VehicleSpectrum:
        """This model with θ also holding the sensors' ``groups`` (their departures from the
        vehicle's; the assumed ones dropped), as the constructor's ``calibrate``: a copy that
        shares the rest (the body's motion cached among it), not a new model (a few ms)."""
        out = copy.copy(self)
        out.calibrate = tuple(g for g in sensor_model.GROUPS if g in groups)
        out._settings = self._settings | {"calibrate": out.calibrate, "sensor_values": None}
        out.names = self.names[: self.noise_slice.stop] + sensor_model.parameter_names(out.calibrate, self.k)
        out.calibration_slice = slice(self.noise_slice.stop, len(out.names))
        out.index = {name: i for i, name in enumerate(out.names)}
        out.n_params = len(out.names)
        out.sensor_values = None
        out.sensing = out.sensing_of(out.vehicle)
        return out

    def assume_sensors(self, sensor_values: np.ndarray) -> None:
        """From now on the model assumes the sensors' departures ``sensor_values``."""
        self._settings["sensor_values"] = sensor_values
        self.sensor_values = sensor_model.unpack(np.asarray(sensor_values, dtype=float), sensor_model.GROUPS,
                                                 self.k)
        self.sensing = self.sensing_of(self.vehicle)

    def set_vehicle(self, vehicle: AnyVehicle, channel_factor: np.ndarray | None = None) -> None:
        """(Re)compute what depends on the assumed vehicle and sensors; ``channel_factor``
        (k,) or (F, k) multiplies each channel's response (a sensor's gain or delay)."""
        v = self.vehicle = vehicle
        w = self.omega
        c = v.corners
        track_m = v.coherence_track_m
        corners = (*(np.asarray(x).tobytes() for x in vars(c).values()), v.wheelbase_m, track_m,
                   gravity_height_m(v))
        if corners != getattr(self, "_corners", None):  # the sensors alone moved: the corners stand
            self._corners, self._body_key = corners, None
            Z, T = self.corner_impedance = corner_matrices(v, 1j * w)  # (F, c, c) each
            B = self.body_map = np.column_stack([np.ones(c.count), -c.x_m, c.y_m])[:, : self.body.coordinates]
            self.body_stiffness = mul(mul(B.T, Z), B)  # Bᵀ Z B
            self.body_input = mul(B.T, T)  # Bᵀ T
            self.gravity_height_m = gravity_height_m(v)
            self.unsprung_total_kg = float(c.unsprung_mass_kg.sum())
            self.body = BodyParameters(self.wheelbase_m, self.rolls, self.gravity_height_m,
                                       self.unsprung_total_kg)
            speeds = np.asarray(self.speed_mps)
            self.mixture = track_mixture(w, v.wheelbase_m, track_m, speeds, self.sample_weights,
                                         self.road_max_cpm, self.fs_hz) if self.varying else None
            share, phi = (self.mixture.share, self.mixture.phi) if self.mixture is not None else \
                (np.ones(w.shape), delay_characteristic(w, v.wheelbase_m, self.speed_mps))
            speed = driving_speed(self.speed_mps, self.sample_weights)  # the budget's coherence
            self.x_coherence = 2.0 * np.pi * np.abs(w / (2.0 * np.pi)) / speed * track_m
            self.delay = np.stack([share, phi.conj(), phi, share], axis=-1).reshape(-1, 2, 2)
        self.sensing = self.sensing_of(v, channel_factor)

    @contextlib.contextmanager
    def assuming(self, vehicle: AnyVehicle, channel_factor: np.ndarray | None = None) -> Iterator[None]:
        """Within the block the model assumes ``vehicle`` (and ``channel_factor``, as
        :meth:`set_vehicle`); after it, its own again as it was (kept, not recomputed)."""
        saved = dict(self.__dict__)
        try:
            self.set_vehicle(vehicle, channel_factor)
            yield
        finally:
            self.__dict__.clear()
            self.__dict__.update(saved)

    def sensing_of(self, v: AnyVehicle, channel_factor: np.ndarray | None = None) -> np.ndarray:
        """iω P (F, k, b): the sensors' accelerations from the body's velocities (q̇) (a gyro's
        rate: P), each channel times its ``channel_factor`` (k,) or (F, k)."""
        w = self.omega
        P, rate = channel_rows(v, self.sensors)  # a gyro reads q̇ itself, not iω q̇
        factor = np.ones((w.size, self.k)) if channel_factor is None else \
            np.broadcast_to(channel_factor, (w.size, self.k))
        out = np.where(rate[None, :, None], 1.0, 1j * w[:, None, None]) * factor[:, :, None] * P[None]
        if self.sensor_values is None:
            return out
        return sensor_model.calibrated(out, w, self.layout, self.sensor_values)

    def sensing_at(self, theta: np.ndarray) -> np.ndarray:
        """The sensing with θ's calibrated values (the assumed one when θ holds none)."""
        if not self.calibrate:
            return self.sensing
        values = sensor_model.unpack(theta[self.calibration_slice], self.calibrate, self.k)
        return sensor_model.calibrated(self.sensing, self.omega, self.layout, values)

    # --- parameters -------------------------------------------------------------------
    def theta(self, params: np.ndarray, road: float, noise: np.ndarray) -> np.ndarray:
        """θ from the body's parameters (:class:`BodyParameters`: the full car's (m, I_xx,
        I_yy, l_f, y_c), the half car's (m, I_yy, l_f)), the road intensity σ² and the noise
        floors (k,)."""
        th = np.zeros(self.n_params)
        th[: self.n_body] = self.body.theta(np.asarray(params, dtype=float))
        th[self.road_index], th[self.waviness_index] = math.log(road), 2.0
        th[self.noise_slice] = np.log(noise)
        return th

    def physical(self, theta: np.ndarray) -> np.ndarray:
        """The body's parameters [kg, kg m², m] from θ (:class:`BodyParameters`' order)."""
        return self.body.physical(theta)

    def physical_jacobian(self, theta: np.ndarray) -> np.ndarray:
        """(n_body, n_params) d(the body's parameters)/dθ."""
        jac = np.zeros((self.n_body, self.n_params))
        jac[:, : self.n_body] = self.body.jacobian(theta)
        return jac

    # --- the model ----------------------------------------------------------------------
    def spectrum(self, theta: np.ndarray, derivatives: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """S (K, k, k) and, if asked, dS/dθ (n_params, K, k, k); NaN where θ overflows."""
        S, dS = self.node_spectrum(theta, derivatives)
        return self.to_targets(S), None if dS is None else self.to_targets(dS)

    def to_targets(self, m: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Matrices at the nodes (..., nodes, k, k) -> at the frequencies (..., K, k, k) or ``rows``."""
        if self._op is None:
            return m if rows is None else m[..., rows, :, :]
        if rows is None:
            return apply(self._op, m)
        key = rows.tobytes()
        if key not in self._row_ops:
            self._row_ops[key] = sparse.csr_array(self._op[rows])
        return apply(self._row_ops[key], m)

    def to_nodes(self, m: np.ndarray) -> np.ndarray:
        """The adjoint of :meth:`to_targets`: ``Σ_k tr(W_k to_targets(X)_k) = Σ_n tr(to_nodes(W)_n X_n)``."""
        return m if self._op_t is None else apply(self._op_t, m)

    def node_spectrum(self, theta: np.ndarray,
                      derivatives: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """As :meth:`spectrum`, S itself at the evaluation grid's nodes."""
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            S, dS = self._spectrum(theta, derivatives)
        if not (np.all(np.isfinite(S)) and (dS is None or np.all(np.isfinite(dS)))):
            S = np.full_like(S, np.nan)
            dS = None if dS is None else np.full_like(dS, np.nan)
        return S, dS

    def _spectrum(self, theta: np.ndarray, derivatives: bool) -> tuple[np.ndarray, np.ndarray | None]:
        sensing = self.sensing_at(theta)
        inv_d, _, _, motion, d_motion = self.body_motion(theta)
        seen = mul(motion, herm(sensing))  # the body's motion as the sensors see it
        per_alias = mul(sensing, seen)  # (F, k, k)
        S_road = self.fold(per_alias)
        noise = np.exp(theta[self.noise_slice])
        S = S_road + np.eye(self.k) * (noise + self.min_noise_psd)
        if not derivatives:
            return S, None
        dS = np.zeros((self.n_params, self.n_freq, self.k, self.k), dtype=complex)
        # ∂D = -ω² ∂M: ∂H = ω² D⁻¹ ∂M H, so ∂(P H R Hᴴ Pᴴ) = ω² P D⁻¹ ∂M (H R Hᴴ) Pᴴ + h.c.
        _, dM = self.body.mass_matrix(theta)
        sensed = mul(sensing, inv_d)
        Q = (self.omega**2)[:, None, None] * sensed
        part = mul(mul(Q[None], dM[:, None]), seen[None])  # (p, F, k, k)
        if self.gravity_height_m != 0.0:  # ∂D/∂ln m also holds the weight's stiffness: ∂H = -D⁻¹ K_g H
            part[0] -= mul(mul(sensed, self.body.gravity_stiffness(theta)), seen)
        # the body's, the road shape's and the coherence's derivatives folded in one pass (one
        # sparse product: the same sums as one each, a fraction of the calls)
        shape = self.shape_basis.shape[0]
        folded = self.fold(np.concatenate([
            part, -self.log_shape[None, :, None, None] * per_alias,
            self.shape_basis[:, :, None, None] * per_alias,
            *([mul(sensing, mul(d_motion, herm(sensing)))[None]] if self.rolls else [])]))
        nb = self.n_body
        dS[:nb] = folded[:nb]
        dS[:nb] += herm(dS[:nb])
        dS[nb] = S_road
        dS[nb + 1: nb + 2 + shape] = folded[nb: nb + 1 + shape]
        if self.rolls:
            dS[self.index["ln_coherence_scale"]] = folded[nb + 1 + shape]
        for i in range(self.k):
            dS[self.noise_slice.start + i, :, i, i] = noise[i]
        if self.calibrate:
            dS[self.calibration_slice] = self.calibration_derivatives(theta)
        return S, dS

    def calibration_derivatives(self, theta: np.ndarray) -> np.ndarray:
        """dS (G, nodes, k, k) at θ by the sensors' calibrated values (``calibrate``): S is
        ``P_s (H R Hᴴ) P_sᴴ`` and the body's motion stays."""
        values = sensor_model.unpack(theta[self.calibration_slice], self.calibrate, self.k)
        d_sensing = sensor_model.derivatives(self.sensing, self.omega, self.layout, values, self.calibrate)
        _, _, _, motion, _ = self.body_motion(theta)
        part = mul(d_sensing, mul(motion, herm(self.sensing_at(theta))))
        return self.fold(part + herm(part))

    def corner_derivatives(self, theta: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """dS (G, nodes, k, k) at θ along ``directions`` (G, values) of the corners' values
        (:func:`~.corner_matrices.corner_response_derivatives`): ``D = Bᵀ Z B -
        ω² M`` and ``Bᵀ T`` move, so ``dH = D⁻¹ (Bᵀ dT - Bᵀ dZ B H)``, and ``d(H R Hᴴ) = dH R Hᴴ
        + h.c.`` — one batched pass instead of a model evaluation per value. The wheels' masses
        also swing with the rotations (``μ h²`` in ``M``, where the vehicle gives its heights)."""
        inv_d, H, weighted_inputs, motion, _ = self.body_motion(theta)
        B = self.body_map
        sensing = self.sensing_at(theta)  # with θ's calibrated sensors, if it holds them
        # P dH R Hᴴ Pᴴ = (P D⁻¹ Bᵀ) (dT R Hᴴ Pᴴ - dZ B H R Hᴴ Pᴴ)
        seen, sensed = mul(motion, herm(sensing)), mul(sensing, inv_d)
        part = corner_response_derivatives(self.vehicle, 1j * self.omega, directions, mul(sensed, B.T),
                                           mul(B, seen), mul(weighted_inputs, mul(herm(H), herm(sensing))))
        if slope := self.body.swing_slope(theta):  # ∂M = slope dM_u on the rotations: ∂H = ω² D⁻¹ ∂M H
            n, rotations = B.shape[0], np.diag([0.0, 1.0, 1.0][: B.shape[1]])
            swing = (self.omega**2)[:, None, None] * mul(mul(sensed, rotations), seen)
            part += slope * np.asarray(directions)[:, 4 * n: 5 * n].sum(axis=1)[:, None, None, None] * swing
        return self.fold(part + herm(part))

    def sensing_derivatives(self, theta: np.ndarray, d_sensing: np.ndarray) -> np.ndarray:
        """dS (G, nodes, k, k) at θ for changes ``d_sensing`` (G, F, k, 3) of :meth:`sensing_of`
        (a sensor's position, gain or timing): S is ``P_s (H R Hᴴ) P_sᴴ`` and the body's
        motion stays."""
        _, _, _, motion, _ = self.body_motion(theta)
        part = mul(d_sensing, mul(motion, herm(self.sensing)))
        return self.fold(part + herm(part))

    def body_motion(self, theta: np.ndarray) -> tuple[np.ndarray, ...]:
        """(D⁻¹, ``H = D⁻¹ Bᵀ T`` (F, 3, 4) the body's response to the wheels' road, the road's
        weighted inputs ``r σ² R``, the body's motion spectrum ``r σ² H R Hᴴ``, its derivative
        in the coherence scale) at θ. Cached at the last θ: a sensor's move leaves it."""
        key = theta[: self.noise_slice.start].tobytes()
        if key == self._body_key and self._body_value is not None:
            return self._body_value
        M, _ = self.body.mass_matrix(theta)
        inv_d = np.linalg.inv(self.body_stiffness + self.body.gravity_stiffness(theta)
                              - (self.omega**2)[:, None, None] * M)
        H = mul(inv_d, self.body_input)
        weight = self.road_weight(theta)[:, None, None]
        if not self.rolls:  # one track: the axles' delay alone
            inputs = weight * self.delay
            motion = mul(mul(H, inputs), herm(H))
            self._body_key, self._body_value = key, (inv_d, H, inputs, motion, np.zeros_like(motion))
            return self._body_value
        scale = math.exp(theta[self.index["ln_coherence_scale"]])
        gamma, d_gamma = self.mixture.coherence(scale) if self.mixture is not None else \
            track_coherence(self.x_coherence * scale)
        inputs = weight * self.road_inputs(gamma)
        motion = mul(mul(H, inputs), herm(H))
        d_motion = mul(mul(H, weight * self.road_inputs(d_gamma, diagonal=0.0)), herm(H))
        self._body_key, self._body_value = key, (inv_d, H, inputs, motion, d_motion)
        return self._body_value

    def road_weight(self, theta: np.ndarray) -> np.ndarray:
        """``r σ²`` (F,): the road velocity's spectrum at the evaluation frequencies."""
        shape = theta[self.shape_slice] @ self.shape_basis if self.shape_basis.size else 0.0
        waviness = theta[self.waviness_index]
        return self.alias_road * np.exp(theta[self.road_index] + (2.0 - waviness) * self.log_shape + shape)

    def road_inputs(self, gamma: np.ndarray, diagonal: float = 1.0,
                    delay: np.ndarray | None = None) -> np.ndarray:
        """R (F, 4, 4): the wheels' road velocity covariance for the tracks' coherence γ (F,) (or
        a mixture's ``G`` (F, 2, 2)) and the axles' ``delay`` (F, 2, 2), default the model's
        ``[[W, φ̄], [φ, W]]``: ``R[f, a, i, b, j] = axles[f, a, b] δ_ij + G[f, a, b] (1 - δ_ij)``."""
        axles = self.delay if delay is None else delay
        G = gamma[:, None, None] * axles if gamma.ndim == 1 else gamma
        eye = np.eye(2)[None, None, :, None, :]
        out = diagonal * axles[:, :, None, :, None] * eye + G[:, :, None, :, None] * (1.0 - eye)
        return out.reshape(-1, 4, 4)

    def fold(self, m: np.ndarray) -> np.ndarray:
        """(..., F, k, k) at the band's nodes and the aliases' -> (..., nodes, k, k): the
        aliases summed and interpolated to the band's nodes."""
        out = m[..., : self.n_freq, :, :]
        if not self.n_alias_terms:
            return out
        lead = m.shape[:-3]
        shape = (*lead, self.n_alias_terms, self.n_alias_nodes, self.k, self.k)
        aliased = m[..., self.n_freq:, :, :].reshape(shape)
        total = aliased.sum(axis=-4)
        return out + (total if self._alias_fold is None else self._alias_fold(total))

