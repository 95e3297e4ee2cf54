"""Inertial parameters of the full car from its three identified body modes (the thesis'
section 2-4, carried from the half car to the whole body).

The body is rigid with three degrees of freedom at its centre of gravity, ``q = (z, φ, θ)``
(heave, pitch nose up, roll left side up; :mod:`rozyn_estimator.vehicle_full`), and mass
matrix ``diag(m, I_yy, I_xx)``. A corner at ``(x_i, y_i)`` moves
``z_i = z + (l_f - x_i) φ + (y_i - y_c) θ`` (``T q``), and the corners push on it with
``F = -Z(s) z_c``: each corner's suspension in series with its tyre (and its unsprung mass
for ``condensed``), the anti-roll bars coupling an axle's two corners — a 4×4 dynamic
stiffness (:func:`corner_stiffness`). A mode ``(s, z_c)`` then satisfies
``s² z_c = -G Z(s) z_c`` with ``G = T diag(m, I_yy, I_xx)⁻¹ Tᵀ`` (the half car's
eq 2-27 with ``M⁻¹`` seen at the corners), and every entry of ``G`` is linear in

    u = (1/m + l_f²/I_yy + y_c²/I_xx, l_f/I_yy, 1/I_yy, y_c/I_xx, 1/I_xx):

``G_ij = u₁ - u₂ (x_i + x_j) + u₃ x_i x_j - u₄ (y_i + y_j) + u₅ y_i y_j``. So, as for the
half car, the least-squares fit is one linear solve (no start point, no local minima),
and ``u`` maps one-to-one to ``(m, I_xx, I_yy, l_f, y_c)``.

The corners' motion in a mode comes from the sensors' by the rigid body: the plane
``z(x, y) = a + b x + c y`` through three or four sensors (least squares with four),
evaluated at the wheels — geometry only, no inertial parameter enters.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.body_model import AnyVehicle, corner_count, corners_of
from rozyn_estimator.gravity import gravity_height_m, rotation_inertia_kgm2, rotation_stiffness_nmprad
from rozyn_estimator.method.fit import _PASSES, STIFFNESS_MODELS
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.vehicle_full import FullVehicle

FULL_PARAM_NAMES = ("mass_kg", "roll_inertia_kgm2", "pitch_inertia_kgm2", "cog_from_front_axle_m",
                    "cog_lateral_m")
"""The full car's estimated parameters, in the order of its estimates and covariance."""


def bar_pairs(v: AnyVehicle) -> list[tuple[int, float]]:
    """The anti-roll bars as (the first of the two corners they join, the track they span [m]):
    the full car's front and rear axles; the half car has none."""
    return [(0, v.track_front_m), (2, v.track_rear_m)] if isinstance(v, FullVehicle) else []


def _series(v: FullVehicle, s: complex, unsprung: bool) -> np.ndarray:
    """(4, 4) the corners' dynamic stiffness at ``s``: suspension (with the bars) between body
    and wheel, tyre between wheel and road; the wheel condensed out (with its mass when
    ``unsprung``): ``Z = Z_s - Z_s (Z_s + Z_t + m_t s²)⁻¹ Z_s``."""
    zs = np.diag(np.asarray(v.suspension_stiffness_npm) + s * np.asarray(v.suspension_damping_nspm)) \
        + corners_of(v).bars_npm
    zt = np.diag(np.asarray(v.tyre_stiffness_npm) + s * np.asarray(v.tyre_damping_nspm))
    if unsprung:
        zt = zt + np.diag(np.asarray(v.unsprung_mass_kg) * s * s)
    return zs - zs @ np.linalg.solve(zs + zt, zs)


def corner_matrices(v: AnyVehicle, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The corners with their wheels condensed exactly, at each of ``s`` (F,): ``(Z, T)``,
    each (F, c, c), with the force on the body at the corners ``F = -Z x_c + T u`` (``u`` the
    road heights under the wheels): ``N = Z_s + Z_t + m_t s²`` the wheels' dynamic stiffness,
    ``Z = Z_s - Z_s N⁻¹ Z_s`` and ``T = Z_s N⁻¹ Z_t`` (the likelihood's corners)."""
    _, zs, zt, A = _corner_parts(v, s)
    zs_a = zs @ A
    return zs - zs_a @ zs, zs_a * zt[:, None, :]


def axle_inverse(n: np.ndarray) -> np.ndarray:
    """The inverse of stacked (F, c, c) matrices that couple only an axle's two corners (0-1,
    2-3: the bars; the half car's two corners are one such pair), each 2×2 block by its
    adjugate. Why not ``np.linalg.inv``: the corners' matrices are rebuilt at every vehicle the
    likelihood assumes, and LAPACK's batched 4×4 inverse was most of that time (0.4 of 0.5 ms
    at 442 frequencies; this: a tenth)."""
    out = np.zeros_like(n)
    for start in range(0, n.shape[-1], 2):
        axle = slice(start, start + 2)
        block = n[:, axle, axle]
        a, b, c, d = block[:, 0, 0], block[:, 0, 1], block[:, 1, 0], block[:, 1, 1]
        det = a * d - b * c
        out[:, axle, axle] = np.stack([np.stack([d, -b], -1), np.stack([-c, a], -1)], -2) / det[:, None, None]
    return out


CORNER_VALUES = ("suspension_stiffness_npm", "suspension_damping_nspm", "tyre_stiffness_npm",
                 "tyre_damping_nspm", "unsprung_mass_kg", "anti_roll_stiffness_front_nmprad",
                 "anti_roll_stiffness_rear_nmprad")
"""The values :func:`corner_matrices` depends on beside the geometry: each corner's five, then
each bar's (the full car's two; :func:`bar_pairs`)."""


def _corner_parts(v: AnyVehicle, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(``s`` (F, 1), ``Z_s`` (F, c, c) with the bars, ``Z_t``'s diagonal (F, c), ``A = N⁻¹``)
    of the corners at ``s``: what the derivatives below share."""
    c = corners_of(v)
    s = np.asarray(s)[:, None]
    eye = np.eye(c.count)
    zs = (c.suspension_stiffness_npm + s * c.suspension_damping_nspm)[:, :, None] * eye + c.bars_npm
    zt = c.tyre_stiffness_npm + s * c.tyre_damping_nspm  # (F, c) diagonal
    A = axle_inverse(zs + (zt + c.unsprung_mass_kg * s * s)[:, :, None] * eye)
    return s, zs, zt, A


def corner_value_count(v: AnyVehicle) -> int:
    """The length of a direction of :data:`CORNER_VALUES` (five per corner, one per bar)."""
    return 5 * corner_count(v) + len(bar_pairs(v))


def corner_matrix_derivatives(v: AnyVehicle, s: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray,
                                                                                              np.ndarray]:
    """``(dZ, dT)`` (G, F, c, c) of :func:`corner_matrices` along ``directions`` (G,
    :func:`corner_value_count`): per direction the change of the :data:`CORNER_VALUES` (each
    corner's for the first five, then the bars'). With ``A = N⁻¹``: ``dZ = dZ_s - dZ_s A Z_s -
    Z_s A dZ_s + Z_s A dN A Z_s`` and ``dT = (dZ_s - Z_s A dN) A Z_t + Z_s A dZ_t`` (``N``,
    ``Z_s`` symmetric, so ``Z_s A = (A Z_s)ᵀ``)."""
    s, zs, zt, A = _corner_parts(v, s)
    n = zt.shape[-1]
    a_zs = A @ zs
    d = np.asarray(directions, dtype=float)
    ks, cs, kt, ct, mu = (d[:, None, n * i: n * i + n] for i in range(5))  # (G, 1, c) each
    bars = np.zeros((d.shape[0], n, n))
    pattern = np.array([[1.0, -1.0], [-1.0, 1.0]])
    for col, (first, track) in enumerate(bar_pairs(v), start=5 * n):
        bars[:, first: first + 2, first: first + 2] = d[:, col, None, None] / track**2 * pattern
    eye = np.eye(n)
    d_zs = (ks + s * cs)[..., None] * eye + bars[:, None]  # (G, F, c, c)
    d_zt = kt + s * ct  # (G, F, c) diagonal
    d_n = d_zs + (d_zt + mu * s * s)[..., None] * eye
    zs_a = a_zs.swapaxes(-1, -2)
    d_z = d_zs - d_zs @ a_zs - zs_a @ d_zs + zs_a @ d_n @ a_zs
    d_t = (d_zs - zs_a @ d_n) @ A * zt[:, None, :] + zs_a * d_zt[..., None, :]
    return d_z, d_t


def corner_response_derivatives(v: AnyVehicle, s: np.ndarray, directions: np.ndarray, left: np.ndarray,
                                q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``left (dT r - dZ q)`` (G, F, k, k) along ``directions`` (G, :func:`corner_value_count`),
    as :func:`corner_matrix_derivatives` (whose ``dZ``, ``dT`` it never forms) with ``left``
    (F, k, c), ``q`` and ``r`` (F, c, k): a spectrum's derivative needs only these products.
    With ``W = q - A Z_s q - A Z_t r`` (``A = N⁻¹``, ``Z_t`` diagonal) it is ``-left (I - Z_s A)
    dZ_s W + left Z_s A (dZ_t (r - q + W) - dm s² (q - W))``, where each ``d·`` is diagonal
    but for the bars' 2×2 blocks: elementwise products, then one batched product of
    (k, 2c) by (2c, k) matrices. Why its own: the corners' calibration takes it at every
    evaluation, and the stacked (G, F, c, c) products were two thirds of that time."""
    s, zs, zt, A = _corner_parts(v, s)
    n = zt.shape[-1]
    zs_a = zs @ A
    w = q - A @ (zs @ q + zt[:, :, None] * r)  # q - A Z_s q - A Z_t r
    in_wheels = q - w  # A Z_s q + A Z_t r
    d = np.asarray(directions, dtype=float)[:, None, :, None]  # (G, 1, values, 1)
    ks, cs, kt, ct, mu = (d[:, :, n * i: n * i + n] for i in range(5))  # (G, 1, c, 1) each
    d_zs_w = (ks + s[..., None] * cs) * w  # the diagonal's part; then the bars'
    for col, (first, track) in enumerate(bar_pairs(v), start=5 * n):
        diff = w[:, first] - w[:, first + 1]  # (F, k)
        bar = d[:, :, col] / track**2 * diff  # (G, F, k)
        d_zs_w[:, :, first] += bar
        d_zs_w[:, :, first + 1] -= bar
    wheel = (kt + s[..., None] * ct) * (r - in_wheels) - mu * (s * s)[..., None] * in_wheels
    stacked = np.concatenate([-d_zs_w, d_zs_w + wheel], axis=2)  # (G, F, 2c, k)
    return np.concatenate([left, left @ zs_a], axis=2) @ stacked


def corner_stiffness(v: FullVehicle, s: complex, model: str) -> np.ndarray:
    """(4, 4) complex dynamic stiffness of the corners at pole ``s`` [N/m], the half car's
    three models (:mod:`rozyn_estimator.method.fit`) in matrix form:

    - ``eq2-21``: the static series connection ``K(0) + s C(0)`` (``C`` its slope at rest);
    - ``eq2-22``: the series connection at the mode's natural frequency ``ω = |s|``,
      ``Re Z(iω) + s Im Z(iω)/ω``;
    - ``condensed``: the exact dynamic condensation of the unsprung masses at ``s``.
    """
    if model not in STIFFNESS_MODELS:
        raise ValueError(f"unknown stiffness model {model!r}; choose from {', '.join(STIFFNESS_MODELS)}")
    if model == "condensed":
        return _series(v, s, unsprung=True)
    if model == "eq2-21":
        h = 1e-3  # rad/s: the slope at rest by a central difference on the imaginary axis
        z0 = _series(v, 0.0, unsprung=False).real
        slope = (_series(v, 1j * h, unsprung=False) - _series(v, -1j * h, unsprung=False)).imag / (2 * h)
        return z0 + s * slope
    w = abs(s)
    z = _series(v, 1j * w, unsprung=False)
    return z.real + s * z.imag / w


def plane_map(points_x_m: Sequence[float], points_y_m: Sequence[float], v: FullVehicle) -> np.ndarray:
    """(4, n) map from the vertical motion of ``n`` body points (three or four, not on one
    line) to the corners' (FL, FR, RL, RR), by the rigid body's plane."""
    pts = np.column_stack([np.ones(len(points_x_m)), points_x_m, points_y_m])
    if pts.shape[0] < 3 or np.linalg.matrix_rank(pts, tol=1e-6 * max(1.0, float(np.abs(pts).max()))) < 3:
        raise IdentificationError("full car: the accelerometers must be three or four points not on one line")
    corners = np.column_stack([np.ones(4), v.corner_x_m, v.corner_y_m])
    return corners @ np.linalg.pinv(pts)


def corner_shapes(v: FullVehicle, modes: Sequence[Mode], sensors: Sequence[int]) -> np.ndarray:
    """(4, n_modes) complex mode shapes at the corners, each of unit norm, from the shapes
    at the accelerometers ``sensors`` (indices into the vehicle's FL, FR, RL, RR sensors)."""
    xs = [v.sensor_x_m[i] for i in sensors]
    ys = [v.sensor_y_m[i] for i in sensors]
    shapes = plane_map(xs, ys, v) @ np.array([md.shape for md in modes]).T
    return shapes / np.linalg.norm(shapes, axis=0)


def fit_full_inertia(v: FullVehicle, modes: Sequence[Mode], sensors: Sequence[int],
                     model: str = "eq2-22") -> np.ndarray:
    """Least-squares ``(m [kg], I_xx [kg m²], I_yy [kg m²], l_f [m], y_c [m])`` from the three
    identified body modes (heave, pitch and roll, in any order).

    Where the vehicle gives its heights, the fit carries the weight through the geometry
    (:mod:`rozyn_estimator.gravity`) as the half car's does: ``-m g h`` on pitch and roll for the
    last pass' mass, ``μ h²`` taken off both fitted inertias.

    Raises:
        IdentificationError: the fit lands outside the physical range.
    """
    h = gravity_height_m(v)
    params = _fit_full_once(v, modes, sensors, model, 0.0)
    for _ in range(_PASSES if h else 0):  # the weight's stiffness: m from the last pass
        gravity = rotation_stiffness_nmprad(params[0], h)
        last, params = params, _fit_full_once(v, modes, sensors, model, gravity)
        if abs(params[0] - last[0]) < 1e-12 * params[0]:
            break
    if h:
        params[1:3] -= rotation_inertia_kgm2(params[0], h, sum(v.unsprung_mass_kg))[0]
    return params


def _fit_full_once(v: FullVehicle, modes: Sequence[Mode], sensors: Sequence[int], model: str,
                   gravity_nmprad: float) -> np.ndarray:
    """One linear fit (:func:`fit_full_inertia`) with the weight's stiffness ``gravity_nmprad``
    on pitch and roll known."""
    x = np.asarray(v.corner_x_m)
    y = np.asarray(v.corner_y_m)
    shapes = corner_shapes(v, modes, sensors)
    body = np.linalg.pinv(np.column_stack([np.ones(4), -x, y]))  # corners -> (z₀, φ, θ)
    rows, target = [], []
    for j, md in enumerate(modes):
        s = md.eigenvalue
        zc = shapes[:, j]
        f = corner_stiffness(v, s, model) @ zc  # the corners' forces on the body, per unit amplitude
        _, phi, theta = body @ zc  # the generalised forces (Σf, -x·f, y·f) gain K_g on the rotations
        total, fx, fy = f.sum(), x @ f - gravity_nmprad * phi, y @ f + gravity_nmprad * theta
        # -(G f)_i = s² z_i, linear in u (module docstring)
        rows.append(np.column_stack([np.full(4, total), -(x * total + fx), x * fx, -(y * total + fy),
                                     y * fy]))
        target.append(-(s * s) * zc)
    design = np.vstack(rows)
    rhs = np.concatenate(target)
    u, *_ = np.linalg.lstsq(np.vstack([design.real, design.imag]), np.concatenate([rhs.real, rhs.imag]),
                            rcond=None)
    return _physical(u, v)


def _physical(u: np.ndarray, v: FullVehicle) -> np.ndarray:
    """``(m, I_xx, I_yy, l_f, y_c)`` from ``u``; IdentificationError outside the physical range."""
    u1, u2, u3, u4, u5 = u
    if not (np.all(np.isfinite(u)) and u3 > 0 and u5 > 0):
        raise IdentificationError(
            f"full-car fit outside the physical range (1/I_yy = {u3:.3g}, 1/I_xx = {u5:.3g})")
    lf, yc = u2 / u3, u4 / u5
    inv_m = u1 - lf * lf * u3 - yc * yc * u5
    half_track = 0.5 * max(v.track_front_m, v.track_rear_m)
    if not (0 < lf < v.wheelbase_m and abs(yc) < half_track and inv_m > 0):
        raise IdentificationError(
            f"full-car fit outside the physical range (lf = {lf:.3g} m, lateral CoG = {yc:.3g} m, "
            f"1/m = {inv_m:.3g})"
        )
    return np.array([1.0 / inv_m, 1.0 / u5, 1.0 / u3, lf, yc])
