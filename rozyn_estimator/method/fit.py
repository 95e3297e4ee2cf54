"""Inertial parameters from identified body modes (thesis section 2-4), for any car.

The body is rigid on its corners (:func:`~rozyn_estimator.body_model.corners_of`: the half
car's two axles on the centreline, the full car's four), with coordinates ``q = (z, φ[, θ])``
at its centre of gravity (heave, pitch nose up and, where it rolls, roll left side up) and
mass matrix ``diag(m, I_yy[, I_xx])``. A corner at ``(x_i, y_i)`` moves ``z_i = z + (l_f -
x_i) φ + (y_i - y_c) θ``, and the corners push on it with ``F = -Z(s) z_c``: each corner's
suspension in series with its tyre (and its unsprung mass for ``condensed``), anti-roll bars
coupling an axle's corners (:func:`corner_stiffness`). A mode ``(s, z_c)`` then satisfies
``s² z_c = -G Z(s) z_c`` with ``G = T M⁻¹ Tᵀ`` (eq 2-27 with ``M⁻¹`` seen at the corners),
and every entry of ``G`` is linear in

    u = (1/m + l_f²/I_yy [+ y_c²/I_xx], l_f/I_yy, 1/I_yy [, y_c/I_xx, 1/I_xx]):

``G_ij = u₁ - u₂ (x_i + x_j) + u₃ x_i x_j [- u₄ (y_i + y_j) + u₅ y_i y_j]``. The least-squares
problem is one linear solve (no start point, no local minima), and ``u`` maps one-to-one to
``(m, I_yy, l_f)`` (the half car's ``(a, p, w)`` of eqs 2-23 to 2-30) or the full car's
``(m, I_xx, I_yy, l_f, y_c)``. The corners' motion in a mode comes from the sensors' by the
rigid body (the line or plane through the sensors, evaluated at the corners): geometry only.

A corner is a complex dynamic stiffness ``z(s) = k + s c`` [N/m]:

- ``eq2-21``: static series stiffness (eq 2-21) and the matching static series damping
  ``(ks^2 ct + kt^2 cs) / (ks + kt)^2`` (the thesis' ``cs ct / (cs + ct)`` ≈ 49 N·s/m
  is not the damping of this connection and is not used);
- ``eq2-22``: eq 2-22 (with the ``omega^2`` the print drops) and its damping companion,
  both evaluated at each identified mode's natural frequency;
- ``condensed``: the exact dynamic condensation of the unsprung mass at the mode's pole,
  ``z = z_s (z_t + m_t s^2) / (z_s + z_t + m_t s^2)``.

The half car's thesis fit (``stiffness-block``) compares the stiffness block of the measured
characteristic matrix A0 (eq 2-20) with the model's (eq 2-27) entry by entry instead.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.body_model import AnyVehicle, Corners
from rozyn_estimator.gravity import gravity_height_m, rotation_inertia_kgm2, rotation_stiffness_nmprad
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.vehicle import Vehicle

STIFFNESS_MODELS = ("eq2-21", "eq2-22", "condensed")
_PASSES = 10  # the weight's stiffness is ~1 % of the pitch stiffness: each pass gains ~2 digits
FIT_KINDS = ("modal", "stiffness-block")


def _checked_model(model: str) -> None:
    if model not in STIFFNESS_MODELS:
        raise ValueError(f"unknown stiffness model {model!r}; choose from {', '.join(STIFFNESS_MODELS)}")


def _corner_scalars(c: Corners, s: complex, model: str) -> np.ndarray:
    """(n,) each corner's dynamic stiffness ``k + s c`` at pole ``s``, without bars."""
    ks, cs, kt, ct, mt = (c.suspension_stiffness_npm, c.suspension_damping_nspm, c.tyre_stiffness_npm,
                          c.tyre_damping_nspm, c.unsprung_mass_kg)
    if model == "condensed":
        zs, zt = ks + s * cs, kt + s * ct + mt * s * s
        return zs * zt / (zs + zt)
    w2 = abs(s) ** 2 if model == "eq2-22" else 0.0
    den = (ks + kt) ** 2 + w2 * (cs + ct) ** 2
    k_eq = (ks * kt**2 + ks**2 * kt + w2 * (ks * ct**2 + kt * cs**2)) / den  # eq 2-21 / 2-22
    c_eq = (ks**2 * ct + kt**2 * cs + w2 * cs * ct * (cs + ct)) / den
    return k_eq + s * c_eq


def corner_impedances(v: Vehicle, s: complex, model: str) -> tuple[complex, complex]:
    """(front, rear) dynamic stiffness ``k + s c`` of the half car's suspension + tyre at pole ``s``."""
    _checked_model(model)
    front, rear = _corner_scalars(v.corners, s, model)
    return complex(front), complex(rear)


def _series(c: Corners, s: complex, unsprung: bool) -> np.ndarray:
    """(n, n) the corners' dynamic stiffness at ``s`` with the bars: suspension between body and
    wheel, tyre between wheel and road, the wheel condensed out (with its mass when
    ``unsprung``): ``Z = Z_s - Z_s (Z_s + Z_t + m_t s²)⁻¹ Z_s``."""
    zs = np.diag(c.suspension_stiffness_npm + s * c.suspension_damping_nspm) + c.bars_npm
    wheel = c.unsprung_mass_kg * s * s if unsprung else 0.0
    zt = np.diag(c.tyre_stiffness_npm + s * c.tyre_damping_nspm + wheel)
    return zs - zs @ np.linalg.solve(zs + zt, zs)


def corner_stiffness(v: AnyVehicle, s: complex, model: str) -> np.ndarray:
    """(n, n) complex dynamic stiffness of the corners at pole ``s`` [N/m] in the three models
    (module docstring); with anti-roll bars, their matrix forms: ``eq2-21`` the static
    connection ``K(0) + s C(0)`` (``C`` its slope at rest), ``eq2-22`` the connection at the
    mode's natural frequency ``ω = |s|``, ``Re Z(iω) + s Im Z(iω)/ω``."""
    _checked_model(model)
    c = v.corners
    if not np.any(c.bars_npm):
        return np.diag(_corner_scalars(c, s, model))
    if model == "condensed":
        return _series(c, s, unsprung=True)
    if model == "eq2-21":
        h = 1e-3  # rad/s: the slope at rest by a central difference on the imaginary axis
        z0 = _series(c, 0.0, unsprung=False).real
        slope = (_series(c, 1j * h, unsprung=False) - _series(c, -1j * h, unsprung=False)).imag / (2 * h)
        return z0 + s * slope
    w = abs(s)
    z = _series(c, 1j * w, unsprung=False)
    return z.real + s * z.imag / w


def _body_columns(x_m: Sequence[float] | np.ndarray, y_m: Sequence[float] | np.ndarray,
                  v: AnyVehicle) -> np.ndarray:
    """(n, 2 or 3) a rigid motion's basis at body points: ``(1, x[, y])``."""
    cols = [np.ones(len(x_m)), np.asarray(x_m, dtype=float)]
    return np.column_stack([*cols, np.asarray(y_m, dtype=float)] if v.ROLLS else cols)


def plane_map(points_x_m: Sequence[float], points_y_m: Sequence[float], v: AnyVehicle) -> np.ndarray:
    """(corners, n) map from the vertical motion of ``n`` body points to the corners', by the
    rigid body: the plane through three or four points not on one line where the body rolls,
    the line through two points at different ``x`` where it does not."""
    pts = _body_columns(points_x_m, points_y_m, v)
    rank, tol = pts.shape[1], 1e-6 * max(1.0, float(np.abs(pts).max()))
    if pts.shape[0] < rank or np.linalg.matrix_rank(pts, tol=tol) < rank:
        raise IdentificationError("full car: the accelerometers must be three or four points not on one line"
                                  if v.ROLLS else "the two accelerometers must sit at different x")
    c = v.corners
    return _body_columns(c.x_m, c.y_m, v) @ np.linalg.pinv(pts)


def corner_shapes(v: AnyVehicle, modes: Sequence[Mode], sensors: Sequence[int] | None = None) -> np.ndarray:
    """(corners, n_modes) complex mode shapes at the corners, each of unit norm, from the
    shapes at the accelerometers ``sensors`` (indices into the vehicle's; None: all)."""
    index = range(len(v.sensor_x_m)) if sensors is None else sensors
    xs, ys = [v.sensor_x_m[i] for i in index], [v.sensor_y_m[i] for i in index]
    shapes = plane_map(xs, ys, v) @ np.array([md.shape for md in modes]).T
    return shapes / np.linalg.norm(shapes, axis=0)


def characteristic_matrix(poles: np.ndarray, shapes: np.ndarray) -> np.ndarray:
    """Measured A0 from two modes and their shapes (eq 2-20), real (4, 4)."""
    lam = np.concatenate([poles, poles.conj()])
    psi = np.concatenate([shapes, shapes.conj()], axis=1)
    basis = np.vstack([psi, psi * lam])
    return np.real(basis @ np.diag(lam) @ np.linalg.inv(basis))


def fit_inertia(v: AnyVehicle, modes: Sequence[Mode], model: str = "eq2-22", kind: str = "modal",
                sensors: Sequence[int] | None = None) -> np.ndarray:
    """Least-squares body parameters from the identified body modes: the half car's ``(m_s [kg],
    I_yy [kg m²], lf [m])`` from two, the full car's ``(m, I_xx, I_yy, l_f, y_c)`` from three
    (heave, pitch and roll, in any order).

    Args:
        v: the vehicle (its corners and geometry are used; its inertial values are not).
        modes: the body modes, their shapes at the accelerometers ``sensors``.
        model: corner stiffness model, one of ``STIFFNESS_MODELS``.
        kind: ``modal`` fits each identified mode, ``s² z_c = -G Z(s) z_c``, where a
            frequency-dependent stiffness is well defined. ``stiffness-block`` (the half car)
            compares the stiffness block of A0 entry by entry (the thesis' fit, with eq 2-21).
            Where the vehicle gives its heights, ``modal`` carries the weight through the
            geometry (:mod:`rozyn_estimator.gravity`): ``-m g h`` on the rotations for the last
            pass' mass (it is ~1 % of the pitch stiffness: a few passes), ``μ h²`` taken off the
            fitted inertias.
        sensors: indices of the vehicle's accelerometers the shapes' components are (None: all).

    Raises:
        IdentificationError: the fit lands outside the physical range.
    """
    if kind not in FIT_KINDS:
        raise ValueError(f"unknown fit kind {kind!r}; choose from {', '.join(FIT_KINDS)}")
    if kind == "stiffness-block" and v.ROLLS:
        raise ValueError("the stiffness-block fit is the half car's (two modes, eq 2-29)")
    _checked_model(model)
    h = gravity_height_m(v) if kind == "modal" else 0.0
    params = _fit_once(v, modes, model, kind, 0.0, sensors)
    for _ in range(_PASSES if h else 0):  # the weight's stiffness: m from the last pass
        last = params
        params = _fit_once(v, modes, model, kind, rotation_stiffness_nmprad(params[0], h), sensors)
        if abs(params[0] - last[0]) < 1e-12 * params[0]:
            break
    if h:  # the fit sees the inertia the body swings with: I + μ h²
        inertias = slice(1, 3) if v.ROLLS else slice(1, 2)
        unsprung_kg = float(v.corners.unsprung_mass_kg.sum())
        params[inertias] -= rotation_inertia_kgm2(params[0], h, unsprung_kg)[0]
    return params


def _fit_once(v: AnyVehicle, modes: Sequence[Mode], model: str, kind: str, gravity_nmprad: float,
              sensors: Sequence[int] | None) -> np.ndarray:
    """One linear fit (:func:`fit_inertia`) with the weight's stiffness through the geometry
    ``gravity_nmprad`` (-m g h for the m of the last pass) on the rotations known."""
    if kind == "stiffness-block":
        return _physical(_stiffness_block(v, modes), v)
    c = v.corners
    x, y = c.x_m, c.y_m
    shapes = corner_shapes(v, modes, sensors)
    body = np.linalg.pinv(_body_columns(x, y, v) * np.r_[1.0, -1.0, 1.0][: 3 if v.ROLLS else 2])
    rows, target = [], []
    for j, md in enumerate(modes):
        s = md.eigenvalue
        zc = shapes[:, j]
        f = corner_stiffness(v, s, model) @ zc  # the corners' forces on the body, per unit amplitude
        motion = body @ zc  # (z₀, φ[, θ]): the generalised forces (Σf, -x·f, y·f) gain K_g on the rotations
        total, fx = f.sum(), x @ f - gravity_nmprad * motion[1]
        cols = [np.full(c.count, total), -(x * total + fx), x * fx]
        if v.ROLLS:
            fy = y @ f + gravity_nmprad * motion[2]
            cols += [-(y * total + fy), y * fy]
        rows.append(np.column_stack(cols))  # -(G f)_i = s² z_i, linear in u (module docstring)
        target.append(-(s * s) * zc)
    design, rhs = np.vstack(rows), np.concatenate(target)
    u, *_ = np.linalg.lstsq(np.vstack([design.real, design.imag]), np.concatenate([rhs.real, rhs.imag]),
                            rcond=None)
    return _physical(u, v)


def _stiffness_block(v: AnyVehicle, modes: Sequence[Mode]) -> np.ndarray:
    """The half car's ``(a, p, w)`` from the stiffness block of A0 (eq 2-29, with eq 2-21)."""
    L = v.wheelbase_m
    poles = np.array([md.eigenvalue for md in modes])
    kf, kr = (z.real for z in _corner_scalars(v.corners, 0.0, "eq2-21"))
    design = np.array([[kf, 0, 0], [kr, -L * kr, 0], [kf, -L * kf, 0], [kr, -2 * L * kr, L * L * kr]])
    target = -characteristic_matrix(poles, corner_shapes(v, modes))[2:, :2].ravel()  # = M^-1 K (eq 2-29)
    u, *_ = np.linalg.lstsq(design, target, rcond=None)
    return u


def _physical(u: np.ndarray, v: AnyVehicle) -> np.ndarray:
    """The body parameters from ``u`` (module docstring); IdentificationError outside the
    physical range."""
    if not v.ROLLS:
        a, p, w = u
        if not (np.isfinite(u).all() and w > 0 and 0 < p / w < v.wheelbase_m and a - p * p / w > 0):
            raise IdentificationError(
                f"fit outside the physical range (1/I = {w:.3g}, lf = {p / w if w else np.nan:.3g} m, "
                f"1/m = {a - p * p / w if w else np.nan:.3g})")
        lf = p / w
        return np.array([1.0 / (a - p * lf), 1.0 / w, lf])
    u1, u2, u3, u4, u5 = u
    if not (np.all(np.isfinite(u)) and u3 > 0 and u5 > 0):
        raise IdentificationError(
            f"full-car fit outside the physical range (1/I_yy = {u3:.3g}, 1/I_xx = {u5:.3g})")
    lf, yc = u2 / u3, u4 / u5
    inv_m = u1 - lf * lf * u3 - yc * yc * u5
    half_track = float(np.abs(v.corners.y_m).max())  # the wider track's half
    if not (0 < lf < v.wheelbase_m and abs(yc) < half_track and inv_m > 0):
        raise IdentificationError(
            f"full-car fit outside the physical range (lf = {lf:.3g} m, lateral CoG = {yc:.3g} m, "
            f"1/m = {inv_m:.3g})")
    return np.array([1.0 / inv_m, 1.0 / u5, 1.0 / u3, lf, yc])
