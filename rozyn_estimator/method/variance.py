"""Variance of an estimate from the data of one window: a robust block jackknife.

The window's start times are cut into G contiguous blocks (each much longer than the
correlation time of the response). Replicate b repeats the identification and fit on
the correlation sums without block b's lagged products (Künsch's blockwise jackknife
for functionals of dependent data); only the per-block correlation sums are extra
work, the replicates reuse the full record's FFTs.

The replicates' influences ``G (theta_b - theta)`` would give the jackknife covariance
through their sample covariance. Near-degenerate modes make the identified mode shapes
locally very sensitive, so a single replicate can jump; the sample variance then
reports several times the real spread (measured over independent roads). The scale of
each parameter's influences is therefore taken from their median absolute deviation
(the normal-consistent MAD), and only their correlation from the sample covariance.
For well-behaved windows this equals the plain jackknife.
"""

from __future__ import annotations

import numpy as np

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
