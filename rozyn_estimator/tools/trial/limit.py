"""``rozyn trial --model full --limit``: the full car's estimate in the limit of infinite data.

One fit (:func:`~rozyn_estimator.method.vehicle_fit.refine.refine`) to the periodogram matrices
averaged over every seed's record of one condition. Averaging removes the records' sampling
scatter but not what the model gets wrong, so the limit's departure from the truth is the
model's own bias (a simulator and an estimator that disagree, a departure the vehicle file does
not describe), measured with a standard error ``std / √n`` (the published std of one record at
the limit, over the seeds) instead of the spread of ``n`` estimates: the bias of ``n`` single
estimates mixes that with the roads' own scatter, whose standard error is the same size but
whose mean also carries what a finite record adds. The fit starts at the truth (the limit is
a property of the model, not of a start), and the estimator is told the vehicle without its
tolerances: a calibration's priors would weigh as against one record's data, not the limit's.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.method.likelihood.spectra import Spectra, window_spectra
from rozyn_estimator.method.vehicle_fit.refine import Refinement, refine
from rozyn_estimator.tools.cars import FULL
from rozyn_estimator.tools.trial.run import parallel_map, parse_seeds, simulate
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.vehicle_full import CORNERS, FullTolerances, FullVehicle

_Z_MODEL = 3.0  # a departure beyond this many standard errors: the model's own bias


@dataclass(frozen=True)
class Limit:
    """The fit to the averaged periodogram of ``n`` records."""

    refinement: Refinement
    truth: np.ndarray  # (5,) the simulated vehicle's (m, I_xx, I_yy, l_f, y_c)
    n: int  # the records averaged

    @property
    def standard_error(self) -> np.ndarray:
        """(5,) the limit's standard error: one record's published std over √n."""
        cov = self.refinement.covariance
        return np.full(5, np.nan) if cov is None else np.sqrt(np.diag(cov) / self.n)

    def to_dict(self) -> dict[str, object]:
        """The JSON record of ``--limit --json``: per parameter (FULL_PARAM_NAMES) in SI units."""
        def named(values: np.ndarray) -> dict[str, float | None]:
            return {k: float(x) if np.isfinite(x) else None
                    for k, x in zip(FULL_PARAM_NAMES, values, strict=True)}

        ref = self.refinement
        return {"model": "full", "limit": True, "n_records": self.n, "status": ref.status,
                "reason": ref.reason,
                "truth": named(self.truth), "params": named(self.truth + self.departure),
                "departure": named(self.departure), "standard_error": named(self.standard_error)}

    @property
    def departure(self) -> np.ndarray:
        """(5,) the limit minus the truth (NaN when the fit failed)."""
        p = self.refinement.params
        return np.full(5, np.nan) if p is None else p - self.truth


def record_spectra(item: tuple[TrialSpec, int]) -> tuple[Spectra, np.ndarray, tuple[int, ...]]:
    """One seed's record: (its spectra in the refinement's band, its speed per sample [m/s],
    the channels' corners)."""
    spec, seed = item
    block = simulate(spec, seed)
    cfg = spec.pipeline_config().likelihood
    fs = spec.rate_hz
    sensors = tuple(CORNERS.index(c) for c in block.channels)
    return window_spectra(block.accel_mps2, fs, cfg.band_at(fs), cfg.taper), block.speed_mps, sensors


def infinite_data_limit(spec: TrialSpec, seeds: Sequence[int], jobs: int | None = None,
                        progress: bool = False) -> Limit:
    """The fit to the periodogram matrices averaged over ``seeds``' records of ``spec``."""
    if not seeds:
        raise ValueError("the limit needs at least one seed")
    total: np.ndarray | None = None
    for record in parallel_map(record_spectra, [(spec, s) for s in seeds], jobs, progress, "record"):
        total = record[0].periodogram.copy() if total is None else total + record[0].periodogram
    assert total is not None
    last, speed, sensors = record  # the seeds' records differ in their roads and noise only
    mean = Spectra(last.freq_hz, total / len(seeds), last.fs_hz, last.n_samples, last.window_dft, last.dft,
                   last.first_bin)
    window = np.zeros((last.n_samples, len(sensors)))  # its length only: the spectra are given
    vehicle = spec.estimator_vehicle
    assert isinstance(vehicle, FullVehicle)
    told = dataclasses.replace(vehicle, tolerances=cast(FullTolerances, FullTolerances.none()))
    ref = refine(window, last.fs_hz, told, sensors, spec.truth, speed,
                      spec.pipeline_config().likelihood, spectra=mean)
    return Limit(ref, spec.truth, len(seeds))


def format_limit(spec: TrialSpec, limit: Limit) -> str:
    """The readable report: per parameter the truth, the limit, its departure and standard error."""
    s = spec
    lines = [f"full car, infinite-data limit: {s.road} class {s.road_class} ({s.amplitudes}), "
             f"{s.speed_kmh:g} km/h, {s.duration_s:g} s records at {s.rate_hz:g} Hz, the periodogram "
             f"averaged over {limit.n} seed(s)", ""]
    ref = limit.refinement
    if not ref.ok:
        return "\n".join([*lines, f"the fit failed: {ref.reason}"])
    se, dep, params = limit.standard_error, limit.departure, limit.truth + limit.departure
    lines.append(f"{'parameter':<26}{'truth':>10}{'limit':>13}{'departure':>12}{'std error':>11}{'z':>7}")
    labels = [f"{p.description} [{p.unit}]" for p in FULL.params]
    for i, label in enumerate(labels):
        lateral = i == 4
        shown = f"{1e3 * dep[i]:+.2f} mm" if lateral else f"{100 * dep[i] / limit.truth[i]:+.3f} %"
        error = f"{1e3 * se[i]:.2f} mm" if lateral else f"{100 * se[i] / limit.truth[i]:.3f} %"
        lines.append(f"{label:<26}{limit.truth[i]:>10.4g}{params[i]:>13.6g}{shown:>12}{error:>11}"
                     f"{dep[i] / se[i]:>+7.1f}")
    beyond = [p.description for i, p in enumerate(FULL.params) if abs(dep[i]) > _Z_MODEL * se[i]]
    lines += ["", f"the model's own bias: {', '.join(beyond)} (beyond {_Z_MODEL:g} standard errors)" if beyond
              else f"no departure beyond {_Z_MODEL:g} standard errors: what single estimates' means show "
                   "beyond this is the records' own scatter"]
    return "\n".join(lines)


def run(spec: TrialSpec, args: argparse.Namespace) -> int:
    """``rozyn trial --model full --limit`` of ``spec`` (the options' trial)."""
    if spec.method != "likelihood":
        raise ConfigError("--limit: the likelihood refinement's limit (--method likelihood)")
    seeds = parse_seeds(args.seeds if args.seeds is not None else str(args.seed))
    limit = infinite_data_limit(spec, seeds, args.jobs, not args.quiet and sys.stderr.isatty())
    print(json.dumps(limit.to_dict()) if args.json else format_limit(spec, limit))
    return 0 if limit.refinement.ok else 1
