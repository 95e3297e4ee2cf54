"""Fixed points ``x = g(x)`` of array maps by Anderson-accelerated iteration.

The nonlinear suspension (:mod:`sim_node.vehicle_plant`) solves a block's extra tensions this
way, each evaluation of ``g`` one vectorised linear run of the half car. Plain iteration
``x <- g(x)`` converges when ``g`` contracts (asymmetric dampers: by at most
``(ratio - 1)/(ratio + 1)`` per step); Anderson's acceleration (Walker & Ni 2011, "type
II", the last ``depth`` differences) takes the least-squares combination of the recent
iterates that best cancels the residual. On a nearly linear map that is GMRES on the
linearised problem: it converges in fewer evaluations (about half here), and also where
plain iteration would not (a progressive spring stiffening near a lightly damped mode).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from rozyn_estimator.errors import ConfigError


@dataclass(frozen=True)
class FixedPoint:
    """A solved fixed point: ``x``, what the map returned beside ``g(x)``, the evaluations."""

    x: np.ndarray
    aux: Any
    evaluations: int


def solve_fixed_point(
    g: Callable[[np.ndarray], tuple[np.ndarray, Any]],
    x0: np.ndarray,
    *,
    rtol: float,
    atol: float,
    max_evaluations: int,
    failure: str,
    depth: int = 5,
) -> FixedPoint:
    """Solve ``x = g(x)`` from ``x0``.

    Args:
        g: the map; returns ``(g(x), aux)``, ``aux`` anything computed on the way.
        x0: first guess (any shape).
        rtol, atol: converged when ``max|g(x) - x| <= rtol max|g(x)| + atol``; the answer
            is that ``x`` (not ``g(x)``), with its own ``aux``.
        max_evaluations: of ``g``.
        failure: what the error says when it does not converge.
        depth: differences kept for the acceleration (0: plain iteration).

    Raises:
        ConfigError: ``failure``, when no convergence (or a non-finite residual) within
            ``max_evaluations``.

    Example:
        >>> solve_fixed_point(lambda x: (np.cos(x), None), np.zeros(1), rtol=1e-12, atol=0.0,
        ...                   max_evaluations=50, failure="cos").x.round(6)
        array([0.739085])
    """
    x = np.asarray(x0, dtype=float)
    d_residual = np.empty((depth, x.size))  # the last differences, in a ring
    d_image = np.empty((depth, x.size))
    kept = 0
    last: tuple[np.ndarray, np.ndarray] | None = None
    size = np.inf
    with np.errstate(over="ignore", invalid="ignore"):  # a diverging iteration ends in the error below
        for k in range(1, max_evaluations + 1):
            image, aux = g(x)
            residual = image - x
            size = float(np.max(np.abs(residual), initial=0.0))
            if not np.isfinite(size):
                break
            if size <= rtol * float(np.max(np.abs(image), initial=0.0)) + atol:
                return FixedPoint(x=x, aux=aux, evaluations=k)
            if last is not None and depth > 0:
                d_residual[kept % depth] = (residual - last[0]).ravel()
                d_image[kept % depth] = (image - last[1]).ravel()
                kept += 1
            last = (residual, image)
            rows = min(kept, depth)
            if rows:
                gamma = _least_squares(d_residual[:rows], residual.ravel())
                x = image - (gamma @ d_image[:rows]).reshape(x.shape)
            else:
                x = image
    raise ConfigError(f"{failure} ({max_evaluations} evaluations, last residual {size:.3g})")


def _least_squares(rows: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``argmin |rows.T @ gamma - target|`` through the small Gram matrix (a few long rows: far
    cheaper than a factorisation of the tall matrix), regularised by 1e-10 of its trace so
    near-dependent rows stay harmless. An overflowing (diverging) history gives no correction."""
    gram = rows @ rows.T
    if not np.all(np.isfinite(gram)):
        return np.zeros(rows.shape[0])
    ridge = 1e-10 * float(np.trace(gram)) + np.finfo(float).tiny
    return np.linalg.solve(gram + ridge * np.eye(rows.shape[0]), rows @ target)


__all__ = ["FixedPoint", "solve_fixed_point"]
