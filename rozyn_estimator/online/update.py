"""One scheduled update of the online estimator: pair the window, check it, run the pipeline.

ROS-free; called by :meth:`OnlineEstimator.compute` outside its lock.
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.method import Estimate, PipelineConfig, estimate
from rozyn_estimator.online.config import OnlineConfig
from rozyn_estimator.online.pairing import pair_channels
from rozyn_estimator.online.records import ERROR, NS, OK, WARN, Job, Update
from rozyn_estimator.vehicle import Vehicle


def compute_update(job: Job, names: tuple[str, str], cfg: OnlineConfig, vehicle: Vehicle,
                   pipeline: PipelineConfig, warm: Estimate | None) -> Update:
    """One update: pair the window's channels, check its fill and speed, run the pipeline."""
    paired = pair_channels(job.front, job.rear, cfg)
    if isinstance(paired, str):
        return Update(job.due_ns, ERROR, paired)
    t_ns, accel, fs = paired
    fill = min(1.0, (t_ns[-1] - t_ns[0]) / NS / cfg.window_s) if t_ns.size > 1 else 0.0
    stamp = int(t_ns[-1]) if t_ns.size else job.due_ns
    if fill < cfg.min_window_fill:
        missing = [n for n, ch in zip(names, (job.front, job.rear), strict=True) if ch[0].size == 0]
        need = f"{cfg.min_window_fill * 100:.0f} % of {cfg.window_s:g} s"
        why = f"waiting for {missing[0]}: no samples in the window" if missing else \
            f"window {fill * 100:.0f} % full (need {need})"
        return Update(stamp, WARN if missing else OK, why, window_fill=fill, fs_hz=fs)
    speed: float | np.ndarray | None = cfg.speed_mps or None
    if job.speed[1].size:
        s = job.speed[1]
        mean_speed = float(np.mean(s))
        if mean_speed > 0 and (s.max() - s.min()) / mean_speed > cfg.max_speed_variation:
            return Update(stamp, WARN, f"speed varied {(s.max() - s.min()) / mean_speed * 100:.0f} % within "
                          f"the window (max {cfg.max_speed_variation * 100:.0f} %): not used",
                          window_fill=fill, fs_hz=fs, speed_mps=mean_speed)
        # one speed per sample: the refinement models the varying wheelbase delay
        speed = np.interp(t_ns.astype(float), job.speed[0].astype(float), s)
    est = estimate(accel, fs, vehicle, pipeline, speed_mps=speed, warm_start=warm)
    speed_mps = None if speed is None else float(np.mean(speed))
    if not est.ok:
        return Update(stamp, WARN, f"identification failed: {est.reason}", est, fill, fs, speed_mps)
    if not _publishable(est):  # never publish a made-up number, whatever the pipeline returns
        why = f"the pipeline returned a non-finite or non-positive estimate {est.params} or covariance"
        return Update(stamp, ERROR, f"update failed (internal error, please report): {why}", None, fill, fs,
                      speed_mps)
    note = "; ".join(est.notes)
    return Update(stamp, WARN if note else OK, note or "estimate published", est, fill, fs, speed_mps)


def _publishable(est: Estimate) -> bool:
    """Finite, positive mass, inertia and CoG distance with a finite covariance."""
    p, cov = est.params, est.covariance
    return (p is not None and p.shape == (3,) and bool(np.all(np.isfinite(p)) and np.all(p > 0))
            and (cov is None or bool(np.all(np.isfinite(cov)))))
