"""Modal identification from free decays (thesis sections 2-2 and 2-3).

The identification step is pluggable: an identifier maps free-decay sequences to
candidate modes; :func:`select_body_modes` then keeps the body modes (two; a full car's three). The thesis'
method is :func:`state_transition_modes` (Zhang & Hayama's state variable method).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view


class IdentificationError(Exception):
    """Identification failed; the message says why (it becomes a failed status)."""


@dataclass(frozen=True)
class Mode:
    """One identified mode.

    ``eigenvalue`` is the s-plane pole [rad/s] with positive imaginary part; ``shape``
    the complex amplitudes at the sensors (front, rear; a full car's four corners) on a
    common scale, largest component 1; ``amplitude`` its share of the initial free-decay amplitude.
    """

    eigenvalue: complex
    shape: tuple[complex, ...]
    amplitude: float

    @property
    def freq_hz(self) -> float:
        """Undamped natural frequency (eq 2-17) [Hz]."""
        return abs(self.eigenvalue) / (2.0 * np.pi)

    @property
    def damping_ratio(self) -> float:
        """eq 2-19."""
        return -self.eigenvalue.real / abs(self.eigenvalue)


Identifier = Callable[[np.ndarray, float, int], list[list[Mode]]]


def state_transition_modes(decays: np.ndarray, dt_s: float, p_blocks: int) -> list[list[Mode]]:
    """All modes of the least-squares state transition matrix, for a batch of records.

    Args:
        decays: (batch, n_refs, n_lags, m) free-decay sequences; each batch item is
            identified on its own from its ``n_refs`` decays (m channels).
        dt_s: sample interval T [s].
        p_blocks: pseudo-measurement blocks p (eq 2-5); the state is ``m * p`` long.

    Returns:
        Per batch item, every mode with a positive imaginary part (one per pair).

    Raises:
        IdentificationError: the decays are too short for ``p_blocks``.
    """
    batch, n_refs, n_lags, m = decays.shape
    n_cols = n_lags - p_blocks  # columns X(k) per decay with X(k + 1) available
    if n_cols * n_refs < p_blocks * m + 2:
        raise IdentificationError(
            f"free decay too short: {n_lags} lags for {p_blocks} pseudo-measurement blocks"
        )
    # X(k) = [Y(k); ...; Y(k + p - 1)] (eq 2-3), all k and references side by side.
    states = sliding_window_view(decays, p_blocks, axis=2)  # (B, R, n_lags - p + 1, m, p)
    states = states.transpose(0, 1, 2, 4, 3).reshape(batch, n_refs, -1, p_blocks * m)
    phi = states[:, :, :-1].reshape(batch, -1, p_blocks * m).transpose(0, 2, 1)  # eq 2-6
    phi_next = states[:, :, 1:].reshape(batch, -1, p_blocks * m).transpose(0, 2, 1)
    # eq 2-9, A1 = (Phi_bar Phi^T)(Phi Phi^T)^-1, with a vanishing ridge so that a
    # noise-free decay (Phi rank deficient) still gives the minimum-norm solution.
    gram = phi @ phi.transpose(0, 2, 1)
    ridge = 1e-12 * np.trace(gram, axis1=1, axis2=2)[:, None, None] * np.eye(gram.shape[1])
    a1 = np.linalg.solve(gram + ridge, phi @ phi_next.transpose(0, 2, 1)).transpose(0, 2, 1)
    z, vecs = np.linalg.eig(a1)
    first = states[:, :, 0].transpose(0, 2, 1)  # (B, m p, R): each decay's first state
    out: list[list[Mode]] = []
    for b in range(batch):
        try:
            coords = np.linalg.solve(vecs[b], first[b])  # modal coordinates: excitation
        except np.linalg.LinAlgError:
            out.append([])
            continue
        keep = (z[b].imag > 0) & (np.abs(z[b]) > 0)
        poles = np.log(z[b][keep]) / dt_s  # eqs 2-12 to 2-16 (principal branch, i.e. atan2)
        shapes = vecs[b][:m, keep]
        amp = np.abs(coords[keep]).sum(axis=1) * np.linalg.norm(shapes, axis=0)
        amp = amp / amp.sum() if amp.sum() > 0 else amp
        modes = []
        for j in range(poles.size):
            shape = shapes[:, j] / shapes[np.argmax(np.abs(shapes[:, j])), j]
            modes.append(Mode(complex(poles[j]), tuple(complex(c) for c in shape), float(amp[j])))
        out.append(modes)
    return out


def select_body_modes(
    modes: Sequence[Mode],
    freq_band_hz: tuple[float, float],
    damping_band: tuple[float, float],
    n_modes: int = 2,
    near: Sequence[Mode] | None = None,
) -> list[Mode]:
    """The body's modes among identified modes (bounce and pitch; a full car's roll too).

    Keeps modes with natural frequency and damping ratio inside the bands (the thesis'
    noise-mode filter). When more remain: the ``n_modes`` that carry the most
    amplitude or, given ``near`` (e.g. the modes of the full record when identifying a
    jackknife replicate), the one closest to each of those, so a replicate follows the
    same modes instead of switching to a different spurious one. Returned sorted by
    frequency.

    Raises:
        IdentificationError: fewer than ``n_modes`` modes in the bands.
    """
    inside = [
        md
        for md in modes
        if freq_band_hz[0] <= md.freq_hz <= freq_band_hz[1]
        and damping_band[0] <= md.damping_ratio <= damping_band[1]
    ]
    if len(inside) < n_modes:
        found = ", ".join(f"{md.freq_hz:.2f} Hz/{md.damping_ratio:.2f}" for md in modes[:12])
        raise IdentificationError(
            f"found {len(inside)} of {n_modes} body modes in {freq_band_hz[0]:g}-{freq_band_hz[1]:g} Hz "
            f"with damping {damping_band[0]:g}-{damping_band[1]:g} (modes seen: {found or 'none'})"
        )
    if near is None:
        chosen = sorted(inside, key=lambda md: md.amplitude, reverse=True)[:n_modes]
    else:
        chosen = []
        for ref in near:
            def distance(md: Mode, ref: Mode = ref) -> float:
                return abs(np.log(md.freq_hz / ref.freq_hz)) + abs(md.damping_ratio - ref.damping_ratio)

            chosen.append(min((md for md in inside if md not in chosen), key=distance))
    return sorted(chosen, key=lambda md: md.freq_hz)


IDENTIFIERS: dict[str, Identifier] = {"state-transition": state_transition_modes}
