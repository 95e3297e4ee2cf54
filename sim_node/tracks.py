"""Two parallel road tracks, left and right, for the full car.

Each track is a :class:`sim_node.road.Road` of the same :class:`~sim_node.road.RoadSpec`
(ISO 8608 with fixed or Gaussian amplitudes, or Bogsjö's Laplace road), so each has the
ISO 8608 PSD ``Gd(n)`` (eq 4-1). The left track is the half car's road of the same seed;
the right one is made from it in the frequency domain so that the two tracks' coherence
(their cross-spectrum over ``Gd``) is a chosen ``gamma(n)``:

- ``gaussian`` amplitudes: ``c_R = gamma c_L + sqrt(1 - gamma^2) c_Y``, ``c_Y`` an
  independent draw of the same PSD: a jointly Gaussian pair with exactly that cross-spectrum;
- ``fixed`` amplitudes (the thesis' generator): ``c_R = c_L exp(i delta)``, ``delta``
  normal with variance ``-2 ln gamma`` per component, so ``E exp(i delta) = gamma``: both
  tracks keep the fixed ISO amplitudes and their cross-spectrum is ``gamma Gd`` on average
  over neighbouring components.

The Laplace road's envelope (a section's roughness) is the road's, shared by both tracks;
it multiplies both, which keeps the coherence up to a smoothing over the envelope's narrow
spectrum (below about ``1 / section_length_m``).

Coherence models (``coherence``):

- ``isotropic`` (default): the road surface as a homogeneous, isotropic Gaussian random
  field whose profile along any line has the PSD ``Gd(n) ~ n^-w`` (Dodds & Robson, "The
  description of road surface roughness", J. Sound Vib. 31(2), 1973; Kamash & Robson,
  "The application of isotropy in road surface modelling", J. Sound Vib. 57(1), 1978).
  Its 2-D spectrum goes as ``|k|^-(w+1)``, and integrating it across (Basset's integral,
  DLMF 10.32.11) gives for tracks ``B`` apart::

      gamma(n) = 2 / Gamma(w/2) * (pi n B)^(w/2) * K_(w/2)(2 pi n B)

  (``K`` the modified Bessel function of the second kind; for ``w = 2``,
  ``gamma = x K_1(x)``, ``x = 2 pi n B``). It is 1 at long wavelengths and falls with
  spatial frequency, below 0.5 from about ``n = 0.2 / B`` (0.13 cycles/m for B = 1.5 m).
- ``identical``: ``gamma = 1``: the right track equals the left one (the half car's road
  under all four wheels: no roll excitation).

The rear wheels run in the front wheels' tracks, ``wheelbase`` later (the simulation
reads the tracks at ``s`` and ``s - wheelbase``); the track separation ``B`` is the front
track width.
"""

from __future__ import annotations

import numpy as np
from scipy.special import gamma as gamma_function
from scipy.special import kv

from sim_node.road import Road, RoadSpec, iso_coefficients, road_grid, spectrum

COHERENCES = ("isotropic", "identical")


def isotropic_coherence(n_cpm: np.ndarray, separation_m: float, waviness: float) -> np.ndarray:
    """Coherence (not squared) of two parallel profiles of an isotropic surface (module docstring).

    Args:
        n_cpm: spatial frequencies [cycles/m], >= 0.
        separation_m: the tracks' lateral distance B [m], >= 0.
        waviness: w of the profile PSD ``Gd ~ n^-w`` (eq 4-1).

    Returns:
        gamma(n) in [0, 1], 1 at n = 0.
    """
    x = 2.0 * np.pi * np.abs(np.asarray(n_cpm, dtype=float)) * separation_m
    order = 0.5 * waviness
    positive = x > 0.0
    xp = np.where(positive, x, 1.0)
    with np.errstate(over="ignore", invalid="ignore"):
        g = 2.0 / gamma_function(order) * (0.5 * xp) ** order * kv(order, xp)
    # far out K underflows to 0 while the power grows: the product is 0 there, not NaN
    return np.where(positive, np.clip(np.nan_to_num(g, nan=0.0), 0.0, 1.0), 1.0)


class RoadTracks:
    """A seeded pair of road tracks (left, right), read at any distances.

    Args:
        spec: the road model of each track.
        seed: the random seed; the left track is ``Road(spec, seed, period_m)``.
        separation_m: lateral distance between the tracks [m] (the front track width).
        period_m: as :class:`~sim_node.road.Road`'s.
        coherence: ``isotropic`` or ``identical`` (module docstring).

    Example:
        >>> tracks = RoadTracks(RoadSpec(), seed=1, separation_m=1.5, period_m=1000.0)
        >>> tracks.heights(np.array([0.0, 10.0])).shape  # (distances, left/right)
        (2, 2)
    """

    def __init__(self, spec: RoadSpec, seed: int, separation_m: float, period_m: float | None = None,
                 coherence: str = "isotropic") -> None:
        if coherence not in COHERENCES:
            raise ValueError(f"coherence must be one of {', '.join(COHERENCES)}, got {coherence!r}")
        if not separation_m >= 0.0:
            raise ValueError(f"separation_m must be >= 0, got {separation_m!r}")
        self.spec = spec
        self.separation_m = float(separation_m)
        self.coherence_model = coherence
        period, n_grid = road_grid(spec, period_m)
        gd, dn = spectrum(spec, period, n_grid)
        left = iso_coefficients(spec, gd, dn, np.random.default_rng([seed, 0]))  # the Road's own draw
        gamma = self.coherence(np.arange(gd.size) * dn)
        rng = np.random.default_rng([seed, 3])  # Road uses streams 0 and 1, the simulation's noise 2
        if spec.amplitudes == "fixed":
            spread = np.sqrt(-2.0 * np.log(np.maximum(gamma, 1e-300)))
            right = left * np.exp(1j * spread * rng.standard_normal(gd.size))
        else:
            right = gamma * left + np.sqrt(1.0 - gamma**2) * iso_coefficients(spec, gd, dn, rng)
        self.left = Road(spec, seed, period, coefficients=left)
        self.right = Road(spec, seed, period, coefficients=right)

    @property
    def period_m(self) -> float:
        return self.left.period_m

    def coherence(self, n_cpm: np.ndarray) -> np.ndarray:
        """The model's coherence gamma(n) (not squared) between the tracks at ``n_cpm``."""
        n = np.asarray(n_cpm, dtype=float)
        if self.coherence_model == "identical":
            return np.ones_like(n)
        return isotropic_coherence(n, self.separation_m, self.spec.waviness)

    def heights(self, s_m: np.ndarray) -> np.ndarray:
        """Road heights [m] at distances ``s_m`` (any shape), stacked last: ``(..., 2)`` left, right."""
        return np.stack([self.left.heights(s_m), self.right.heights(s_m)], axis=-1)


__all__ = ["COHERENCES", "RoadTracks", "isotropic_coherence"]
