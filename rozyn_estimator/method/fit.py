"""Inertial parameters from identified modes (thesis section 2-4).

The body is the 2-DOF equivalent half car of eqs 2-23 to 2-30 in the axle coordinates
``[x_sf, x_sr]``: mass matrix eq 2-28, stiffness and damping in the listing's (correct)
form ``K = [[k_f, k_r], [lf k_f, -lr k_r]]``. Each corner is the suspension in series
with the tyre, as a complex dynamic stiffness ``z(s) = k + s c`` [N/m]:

- ``eq2-21``: static series stiffness (eq 2-21) and the matching static series damping
  ``(ks^2 ct + kt^2 cs) / (ks + kt)^2`` (the thesis' ``cs ct / (cs + ct)`` ≈ 49 N·s/m
  is not the damping of this connection and is not used);
- ``eq2-22``: eq 2-22 (with the ``omega^2`` the print drops) and its damping companion,
  both evaluated at each identified mode's natural frequency;
- ``condensed``: the exact dynamic condensation of the unsprung mass at the mode's pole,
  ``z = z_s (z_t + m_t s^2) / (z_s + z_t + m_t s^2)``.

The fit compares the measured characteristic matrix A0 (eq 2-20) with the model's
(eq 2-27). With ``M^-1 = [[1/m, lf/I], [1/m, -lr/I]]`` every residual is linear in
``(a, p, w) = (1/m + lf^2/I, lf/I, 1/I)``, a one-to-one map of ``(m, I, lf)``: the
least-squares problem is solved exactly by one linear solve, with no start point and
no local minima.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rozyn_estimator.gravity import gravity_height_m, rotation_inertia_kgm2, rotation_stiffness_nmprad
from rozyn_estimator.method.identification import IdentificationError, Mode
from rozyn_estimator.vehicle import Vehicle

STIFFNESS_MODELS = ("eq2-21", "eq2-22", "condensed")
_PASSES = 10  # the weight's stiffness is ~1 % of the pitch stiffness: each pass gains ~2 digits
FIT_KINDS = ("modal", "stiffness-block")


def corner_impedances(v: Vehicle, s: complex, model: str) -> tuple[complex, complex]:
    """(front, rear) dynamic stiffness ``k + s c`` of suspension + tyre at pole ``s``."""
    if model not in STIFFNESS_MODELS:
        raise ValueError(f"unknown stiffness model {model!r}; choose from {', '.join(STIFFNESS_MODELS)}")
    corners = (
        (v.suspension_stiffness_front_npm, v.suspension_damping_front_nspm,
         v.tyre_stiffness_front_npm, v.tyre_damping_front_nspm, v.unsprung_mass_front_kg),
        (v.suspension_stiffness_rear_npm, v.suspension_damping_rear_nspm,
         v.tyre_stiffness_rear_npm, v.tyre_damping_rear_nspm, v.unsprung_mass_rear_kg),
    )
    out = []
    for ks, cs, kt, ct, mt in corners:
        if model == "condensed":
            zs, zt = ks + s * cs, kt + s * ct + mt * s * s
            out.append(zs * zt / (zs + zt))
            continue
        w2 = abs(s) ** 2 if model == "eq2-22" else 0.0
        den = (ks + kt) ** 2 + w2 * (cs + ct) ** 2
        k_eq = (ks * kt**2 + ks**2 * kt + w2 * (ks * ct**2 + kt * cs**2)) / den  # eq 2-21 / 2-22
        c_eq = (ks**2 * ct + kt**2 * cs + w2 * cs * ct * (cs + ct)) / den
        out.append(k_eq + s * c_eq)
    return out[0], out[1]


def sensor_to_axle(v: Vehicle) -> np.ndarray:
    """(2, 2) map from sensor amplitudes to axle amplitudes of the rigid body."""
    L = v.wheelbase_m
    to_sensor = np.array([[1.0 - x / L, x / L] for x in v.sensor_x_m])
    return np.linalg.inv(to_sensor)


def axle_shapes(v: Vehicle, modes: Sequence[Mode]) -> np.ndarray:
    """(2, n_modes) complex mode shapes at the axles, each of unit norm."""
    shapes = sensor_to_axle(v) @ np.array([md.shape for md in modes]).T
    return shapes / np.linalg.norm(shapes, axis=0)


def characteristic_matrix(poles: np.ndarray, shapes: np.ndarray) -> np.ndarray:
    """Measured A0 from two modes and their shapes (eq 2-20), real (4, 4)."""
    lam = np.concatenate([poles, poles.conj()])
    psi = np.concatenate([shapes, shapes.conj()], axis=1)
    basis = np.vstack([psi, psi * lam])
    return np.real(basis @ np.diag(lam) @ np.linalg.inv(basis))


def fit_inertia(
    v: Vehicle, modes: Sequence[Mode], model: str = "eq2-22", kind: str = "modal"
) -> np.ndarray:
    """Least-squares (m_s [kg], I_yy [kg m^2], lf [m]) from two identified modes.

    Args:
        v: the vehicle (its suspension, tyres, unsprung masses and geometry are used;
            its sprung mass, inertia and CoG are not).
        modes: the two body modes.
        model: corner stiffness model, one of ``STIFFNESS_MODELS``.
        kind: ``modal`` compares A0 with the model's on each identified mode, where a
            frequency-dependent stiffness is well defined; as A0 has the modes as its
            eigenvectors (eq 2-20), ``A0 v_j = s_j v_j`` is the measured side.
            ``stiffness-block`` compares the stiffness block of A0 entry by entry (the
            thesis' fit, with eq 2-21). Where the vehicle gives its heights, ``modal``
            carries the weight through the geometry (:mod:`rozyn_estimator.gravity`): its
            stiffness for the last pass' mass (it is ~1 % of the pitch stiffness: a few
            passes), its inertia taken off the fitted one.

    Raises:
        IdentificationError: the fit lands outside the physical range.
    """
    if kind not in FIT_KINDS:
        raise ValueError(f"unknown fit kind {kind!r}; choose from {', '.join(FIT_KINDS)}")
    h = gravity_height_m(v)
    params = _fit_once(v, modes, model, kind, 0.0)
    for _ in range(_PASSES if h and kind == "modal" else 0):  # the weight's stiffness: m from the last pass
        last, params = params, _fit_once(v, modes, model, kind, rotation_stiffness_nmprad(params[0], h))
        if abs(params[0] - last[0]) < 1e-12 * params[0]:
            break
    if h and kind == "modal":  # the fit sees the inertia the body swings with: I + μ h²
        unsprung_kg = v.unsprung_mass_front_kg + v.unsprung_mass_rear_kg
        params[1] -= rotation_inertia_kgm2(params[0], h, unsprung_kg)[0]
    return params


def _fit_once(v: Vehicle, modes: Sequence[Mode], model: str, kind: str, gravity_nmprad: float) -> np.ndarray:
    """One linear fit (:func:`fit_inertia`) with the weight's pitch stiffness through the
    geometry ``gravity_nmprad`` (-m g h for the m of the last pass) known."""
    L = v.wheelbase_m
    poles = np.array([md.eigenvalue for md in modes])
    shapes = axle_shapes(v, modes)
    if kind == "stiffness-block":
        kf, kr = (z.real for z in corner_impedances(v, 0.0, "eq2-21"))
        design = np.array([[kf, 0, 0], [kr, -L * kr, 0], [kf, -L * kf, 0], [kr, -2 * L * kr, L * L * kr]])
        target = -characteristic_matrix(poles, shapes)[2:, :2].ravel()  # = M^-1 K (eq 2-29)
    else:
        rows, target_parts = [], []
        for j, s in enumerate(poles):
            zf, zr = corner_impedances(v, s, model)
            psi = shapes[:, j]
            total = zf * psi[0] + zr * psi[1]  # vertical force per unit amplitude
            rear = zr * psi[1] - gravity_nmprad * (psi[0] - psi[1]) / L**2  # with K_g = -m g h on the pitch
            # -M^-1 Z psi = s^2 psi (lower rows of A0 v = s v), linear in (a, p, w)
            rows += [[total, -L * rear, 0.0], [total, -L * (total + rear), L * L * rear]]
            target_parts += list(-(s * s) * psi)
        cplx = np.array(rows, dtype=complex)
        design = np.vstack([cplx.real, cplx.imag])
        target = np.concatenate([np.real(target_parts), np.imag(target_parts)])
    (a, p, w), *_ = np.linalg.lstsq(design, target, rcond=None)
    if not (np.isfinite([a, p, w]).all() and w > 0 and 0 < p / w < L and a - p * p / w > 0):
        raise IdentificationError(
            f"fit outside the physical range (1/I = {w:.3g}, lf = {p / w if w else np.nan:.3g} m, "
            f"1/m = {a - p * p / w if w else np.nan:.3g})"
        )
    lf = p / w
    return np.array([1.0 / (a - p * lf), 1.0 / w, lf])
