"""Rozyn's stage on a checked window, for either car (thesis sections 2-1 to 2-4): the
correlation functions of every channel pair as free decays, the state transition matrix's
modes, the body modes (two for the half car, heave and pitch; three for the full car, and
roll) by their frequency and damping bands and amplitude, the linear fit
(:func:`~rozyn_estimator.method.fit.fit_inertia`) and the covariance of a robust block
jackknife (:func:`jackknife_covariance`).

The jackknife: the window's start times are cut into G contiguous blocks (each much longer
than the correlation time of the response). Replicate b repeats the identification and fit
on the correlation sums without block b's lagged products (Künsch's blockwise jackknife for
functionals of dependent data); only the per-block correlation sums are extra work, the
replicates reuse the full record's FFTs.

The replicates' influences ``G (theta_b - theta)`` would give the jackknife covariance
through their sample covariance. Near-degenerate modes make the identified mode shapes
locally very sensitive, so a single replicate can jump; the sample variance then
reports several times the real spread (measured over independent roads). The scale of
each parameter's influences is therefore taken from their median absolute deviation
(the normal-consistent MAD), and only their correlation from the sample covariance.
For well-behaved windows this equals the plain jackknife.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from rozyn_estimator.body_model import AnyVehicle
from rozyn_estimator.method.config import PipelineConfig
from rozyn_estimator.method.correlation import correlation_sums, lag_range
from rozyn_estimator.method.fit import fit_inertia
from rozyn_estimator.method.glitches import InputError
from rozyn_estimator.method.identification import IDENTIFIERS, IdentificationError, Mode, select_body_modes

N_DOF_FULL = 7  # eq 2-4's n for the full car: body heave, pitch, roll and four wheels



MIN_SUCCESS_SHARE = 0.7  # fewer successful replicates than this: no honest variance
_MAD_TO_STD = 1.4826  # MAD of a normal sample -> its standard deviation


def jackknife_covariance(replicates: np.ndarray, full: np.ndarray) -> tuple[np.ndarray | None, int]:
    """Covariance from delete-one-block replicates.

    Args:
        replicates: (G, k) estimates without one block each, NaN rows where a
            replicate failed.
        full: (k,) the full-record estimate.

    Returns:
        ((k, k) covariance, or None when fewer than 70 % of replicates succeeded;
        the number that succeeded).
    """
    ok = np.all(np.isfinite(replicates), axis=1)
    g = int(ok.sum())
    if g < max(3, MIN_SUCCESS_SHARE * replicates.shape[0]):
        return None, g
    dev = replicates[ok] - full
    centre = np.median(dev, axis=0)
    # jackknife variance (g - 1)/g * sum (dev - mean)^2 ~ (g - 1) * spread^2
    scale = np.sqrt(g - 1) * _MAD_TO_STD * np.median(np.abs(dev - centre), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.nan_to_num(np.corrcoef(dev, rowvar=False))
    np.fill_diagonal(corr, 1.0)
    return corr * np.outer(scale, scale), g


def rozyn_fit(y: np.ndarray, fs_hz: float, v: AnyVehicle, cfg: PipelineConfig, speed_mps: float | None,
              sensors: tuple[int, ...] | None = None,
              ) -> tuple[np.ndarray, np.ndarray | None, tuple[Mode, ...], tuple[str, ...]]:
    """(the body parameters, their jackknife covariance or None, the body modes, notes) of the
    demeaned window ``y`` whose columns are the vehicle's accelerometers ``sensors`` (None:
    all); raises InputError, IdentificationError or LinAlgError where the stage cannot."""
    n, dt = y.shape[0], 1.0 / fs_hz
    if v.ROLLS:  # the full car's decays are always the multi-reference ones
        cfg = cfg.replace(correlation="multi-reference")
    first, last = lag_range(cfg, fs_hz, v, speed_mps)
    p_blocks = _p_blocks(cfg, v, y.shape[1])
    if cfg.correlation == "free-decay":
        params, modes = _fitted(IDENTIFIERS[cfg.identifier](y[None, None, first:], dt, p_blocks)[0], v, cfg,
                                sensors)
        return params, None, modes, ()
    jackknife = cfg.variance == "jackknife"
    blocks = cfg.jackknife_blocks if jackknife else 1
    if n < blocks * (last + 1) or n < 4 * (last + 1):
        raise InputError(f"window too short for {cfg.max_lag_s:g} s of correlation lags in {blocks} blocks: "
                         f"{n / fs_hz:.1f} s")
    sums = correlation_sums(y, last, blocks)
    total = sums.sum(axis=0)
    records = [total] + ([total - sums[b] for b in range(blocks)] if jackknife else [])  # b: without block b
    decays = np.stack([free_decays(r, first, cfg) for r in records])
    identified = IDENTIFIERS[cfg.identifier](decays, dt, p_blocks)
    params, body = _fitted(identified[0], v, cfg, sensors)
    if not jackknife:
        return params, None, body, ()
    replicates = np.full((blocks, params.size), np.nan)
    for b, found in enumerate(identified[1:]):
        with contextlib.suppress(IdentificationError, np.linalg.LinAlgError):  # a failed one: NaN
            replicates[b] = _fitted(found, v, cfg, sensors, near=body)[0]
    cov, good = jackknife_covariance(replicates, params)
    if cov is None:
        raise IdentificationError(
            f"unstable identification: only {good} of {blocks} jackknife replicates found the modes")
    notes = () if good == blocks else (f"{blocks - good} of {blocks} jackknife replicates failed",)
    return params, cov, body, notes


def fit_correlations(corr: np.ndarray, first: int, fs_hz: float, v: AnyVehicle, cfg: PipelineConfig,
                     sensors: tuple[int, ...] | None = None) -> tuple[np.ndarray, tuple[Mode, ...]]:
    """(the body parameters, the body modes) from (lags, k, k) correlation sums from lag
    ``first`` on, as :func:`rozyn_fit` fits a window's (no jackknife)."""
    decays = free_decays(corr, first, cfg)[None]
    return _fitted(IDENTIFIERS[cfg.identifier](decays, 1.0 / fs_hz, _p_blocks(cfg, v, corr.shape[1]))[0],
                   v, cfg, sensors)


def _p_blocks(cfg: PipelineConfig, v: AnyVehicle, channels: int) -> int:
    """Pseudo-measurement blocks ``p = γ 2n/m`` (eq 2-5) for ``channels`` sensors: the full car's
    ``n`` at least its seven degrees of freedom."""
    return math.ceil(cfg.gamma * 2 * (max(cfg.n_dof, N_DOF_FULL) if v.ROLLS else cfg.n_dof) / channels)


def _fitted(modes: list[Mode], v: AnyVehicle, cfg: PipelineConfig, sensors: tuple[int, ...] | None,
            near: tuple[Mode, ...] | None = None) -> tuple[np.ndarray, tuple[Mode, ...]]:
    """(the body parameters, the body modes) from identified ``modes``: the half car's two and
    ``cfg.fit`` (the thesis' stiffness-block fit is the half car's), the full car's three and
    the modal fit; with ``near``, the modes closest to those (a jackknife replicate)."""
    n_modes, kind = (3, "modal") if v.ROLLS else (2, cfg.fit)
    body = select_body_modes(modes, cfg.freq_band_hz, cfg.damping_band, n_modes=n_modes, near=near)
    return fit_inertia(v, body, cfg.stiffness_model, kind, sensors), tuple(body)


def free_decays(corr: np.ndarray, first: int, cfg: PipelineConfig) -> np.ndarray:
    """(n_refs, n_lags, k) free-decay sequences from (lags, k, k) correlation sums: reference
    j's ``[R_0j(tau), …, R_kj(tau)]`` (multi-reference), or the thesis' per-channel
    autocorrelations each normalised by its variance (one reference)."""
    if cfg.correlation == "thesis-acf":
        k = corr.shape[1]
        acf = np.column_stack([corr[:, i, i] / corr[0, i, i] for i in range(k)])
        return acf[None, first:]
    return corr[first:].transpose(2, 0, 1)
