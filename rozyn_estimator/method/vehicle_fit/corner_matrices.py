"""The corners under the body as the likelihood's spectral model sees them, for any car: each
corner's suspension (with the anti-roll bars between an axle's corners) above its wheel above
its tyre, the wheel condensed out exactly at each frequency (:func:`corner_matrices`), and the
derivatives of that along the corners' values (the calibration's and the budget's).
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.body_model import AnyVehicle, corner_count
from rozyn_estimator.method.vehicle_fit.stacks import mul


def bar_pairs(v: AnyVehicle) -> list[tuple[int, float]]:
    """The anti-roll bars as (the first of the two corners they join, the track they span [m]):
    the full car's front and rear axles; the half car has none."""
    return [(bar.first, bar.track_m) for bar in v.corners.bars]


def corner_matrices(v: AnyVehicle, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The corners with their wheels condensed exactly, at each of ``s`` (F,): ``(Z, T)``,
    each (F, c, c), with the force on the body at the corners ``F = -Z x_c + T u`` (``u`` the
    road heights under the wheels): ``N = Z_s + Z_t + m_t s²`` the wheels' dynamic stiffness,
    ``Z = Z_s - Z_s N⁻¹ Z_s`` and ``T = Z_s N⁻¹ Z_t`` (the likelihood's corners)."""
    _, zs, zt, A = _corner_parts(v, s)
    zs_a = mul(zs, A)
    return zs - mul(zs_a, zs), zs_a * zt[:, None, :]


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


def _corner_parts(v: AnyVehicle, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(``s`` (F, 1), ``Z_s`` (F, c, c) with the bars, ``Z_t``'s diagonal (F, c), ``A = N⁻¹``)
    of the corners at ``s``: what the derivatives below share."""
    c = v.corners
    s = np.asarray(s)[:, None]
    eye = np.eye(c.count)
    zs = (c.suspension_stiffness_npm + s * c.suspension_damping_nspm)[:, :, None] * eye + c.bars_npm
    zt = c.tyre_stiffness_npm + s * c.tyre_damping_nspm  # (F, c) diagonal
    A = axle_inverse(zs + (zt + c.unsprung_mass_kg * s * s)[:, :, None] * eye)
    return s, zs, zt, A


def corner_value_count(v: AnyVehicle) -> int:
    """The length of a direction of the corner values (:attr:`~rozyn_estimator.corners.Corners.values`:
    five per corner, one per bar)."""
    return 5 * corner_count(v) + len(bar_pairs(v))


def corner_matrix_derivatives(v: AnyVehicle, s: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray,
                                                                                              np.ndarray]:
    """``(dZ, dT)`` (G, F, c, c) of :func:`corner_matrices` along ``directions`` (G,
    :func:`corner_value_count`): per direction the change of the corner values (each
    corner's for the first five, then the bars'). With ``A = N⁻¹``: ``dZ = dZ_s - dZ_s A Z_s -
    Z_s A dZ_s + Z_s A dN A Z_s`` and ``dT = (dZ_s - Z_s A dN) A Z_t + Z_s A dZ_t`` (``N``,
    ``Z_s`` symmetric, so ``Z_s A = (A Z_s)ᵀ``)."""
    s, zs, zt, A = _corner_parts(v, s)
    n = zt.shape[-1]
    a_zs = mul(A, zs)
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
    d_z = d_zs - mul(d_zs, a_zs) - mul(zs_a, d_zs) + mul(mul(zs_a, d_n), a_zs)
    d_t = mul(d_zs - mul(zs_a, d_n), A) * zt[:, None, :] + zs_a * d_zt[..., None, :]
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
    zs_a = mul(zs, A)
    w = q - mul(A, mul(zs, q) + zt[:, :, None] * r)  # q - A Z_s q - A Z_t r
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
    return mul(np.concatenate([left, mul(left, zs_a)], axis=2), stacked)
