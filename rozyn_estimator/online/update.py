"""One scheduled update of the online estimator: align the window, check it, run the pipeline.

ROS-free; called by :meth:`OnlineEstimator.compute` outside its lock. It runs
:func:`~rozyn_estimator.method.estimate` on the layout's channels, either car.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
from threadpoolctl import ThreadpoolController

from rozyn_estimator.method import Estimate, PipelineConfig, estimate
from rozyn_estimator.method.drive import speed_spread, window_speed
from rozyn_estimator.online.config import OnlineConfig
from rozyn_estimator.online.driving import driving_time_s, standing
from rozyn_estimator.online.pairing import align_channels
from rozyn_estimator.online.records import ERROR, HALF_LAYOUT, NS, OK, WARN, Job, Layout, Update
from rozyn_estimator.vehicle import Vehicle
from rozyn_estimator.vehicle_full import FullVehicle


def compute_update(job: Job, names: Sequence[str], cfg: OnlineConfig, vehicle: Vehicle | FullVehicle,
                   pipeline: PipelineConfig, warm: Estimate | None,
                   layout: Layout = HALF_LAYOUT) -> Update:
    """One update: align the window's channels, check its fill and speed, run the pipeline.

    Args:
        job: the due window.
        names: what to call each channel (e.g. its topic).
        cfg: window and schedule settings.
        vehicle: the half car or the full car (``layout`` must be its).
        pipeline: settings of the update.
        warm: the last published estimate of this window's generation (the warm start).
        layout: the vehicle model's channels and parameters.
    """
    with _one_blas_thread():
        return _compute(job, names, cfg, vehicle, pipeline, warm, layout)


def _one_blas_thread() -> Any:
    """A context in which the BLAS libraries use one thread: the node's own count
    (``glue.spin_node``), so that the demo, a replay and a study compute what the node does bit
    for bit (with two threads a BLAS library splits its sums otherwise: the full car's estimates
    moved in their sixth digit)."""
    return _controller().limit(limits=1, user_api="blas")


@functools.cache
def _controller() -> ThreadpoolController:
    """The BLAS libraries loaded (numpy's and scipy's are by the first update); made once:
    finding them costs 0.6 ms, limiting them then 0.01 ms."""
    return ThreadpoolController()


def _compute(job: Job, names: Sequence[str], cfg: OnlineConfig, vehicle: Vehicle | FullVehicle,
             pipeline: PipelineConfig, warm: Estimate | None, layout: Layout) -> Update:
    """:func:`compute_update`'s work."""
    paired = align_channels(job.samples, cfg)
    if isinstance(paired, str):
        return Update(job.due_ns, ERROR, paired)
    t_ns, accel, fs = paired
    stamp = int(t_ns[-1]) if t_ns.size else job.due_ns
    stands = standing(job.speed, cfg.driving_speed_mps)
    if stands is not None:  # at a stop the last estimate stands: a stack reading it has the current answer
        if warm is not None and warm.ok:
            return Update(stamp, OK, f"held: the vehicle stands ({stands:.1f} m/s); the last estimate stands",
                          warm, fs_hz=fs, speed_mps=stands, held=True)
        return Update(stamp, OK, f"the vehicle stands ({stands:.1f} m/s): no estimate yet", fs_hz=fs,
                      speed_mps=stands)
    span = (t_ns[-1] - t_ns[0]) / NS if t_ns.size > 1 else 0.0
    driving = driving_time_s(job.speed, int(t_ns[0]), int(t_ns[-1]), cfg.driving_speed_mps) \
        if job.speed[1].size and t_ns.size > 1 else span  # standing time does not fill the window
    fill = min(1.0, driving / cfg.window_s)
    if fill < cfg.min_window_fill:
        missing = [n for n, ch in zip(names, job.samples, strict=True) if ch[0].size == 0]
        need = f"{cfg.min_window_fill * 100:.0f} % of {cfg.window_s:g} s"
        why = f"waiting for {missing[0]}: no samples in the window" if missing else \
            f"window {fill * 100:.0f} % full (need {need}{' of driving' if driving < span else ''})"
        return Update(stamp, WARN if missing else OK, why, window_fill=fill, fs_hz=fs)
    speed: float | np.ndarray | None = cfg.speed_mps or None
    silent = _speed_silence_s(job, t_ns) if job.speed_source else 0.0
    if silent > cfg.speed_silence_s:
        return Update(stamp, WARN, f"the speed topic was silent for {silent:.1f} s of the window (limit "
                      f"{cfg.speed_silence_s:g} s; or sent no valid speed): its speed is unknown, not used",
                      window_fill=fill, fs_hz=fs)
    if job.speed[1].size:
        s = job.speed[1]
        spread = speed_spread(s)
        if spread > cfg.max_speed_variation:
            return Update(stamp, WARN, f"speed varied {spread * 100:.0f} % within the window (max "
                          f"{cfg.max_speed_variation * 100:.0f} %): not used", window_fill=fill, fs_hz=fs,
                          speed_mps=float(np.mean(s)))
        # one speed per sample: the refinement models the varying wheelbase delay
        speed = np.interp(t_ns.astype(float), job.speed[0].astype(float), s)
    est = estimate(accel, fs, vehicle, pipeline, speed_mps=speed, warm_start=warm, sensors=layout.channels)
    speed_mps = window_speed(speed)[0]
    if not est.ok:
        return Update(stamp, WARN, f"identification failed: {est.reason}", est, fill, fs, speed_mps)
    if not _publishable(est, layout):  # never publish a made-up number, whatever the pipeline returns
        why = f"the pipeline returned a non-finite or non-positive estimate {est.params} or covariance"
        return Update(stamp, ERROR, f"update failed (internal error, please report): {why}", None, fill, fs,
                      speed_mps)
    note = "; ".join(est.notes)
    return Update(stamp, WARN if note else OK, note or "estimate published", est, fill, fs, speed_mps)


def _speed_silence_s(job: Job, t_ns: np.ndarray) -> float:
    """The longest stretch of the window without a valid speed sample [s] (its ends included:
    a speed that stopped before the window's end is as unknown there as a missing one)."""
    edges = np.concatenate(([t_ns[0]], job.speed[0], [t_ns[-1]])).astype(float)
    return float(np.max(np.diff(edges), initial=0.0)) / NS


def _publishable(est: Estimate, layout: Layout) -> bool:
    """Finite estimates with a finite covariance; mass, inertias and CoG distance positive (the
    full car's lateral CoG may have either sign)."""
    p, cov, k = est.params, est.covariance, len(layout.params)
    return (p is not None and p.shape == (k,) and bool(np.all(np.isfinite(p)))
            and bool(np.all(p[:layout.positive] > 0)) and (cov is None or bool(np.all(np.isfinite(cov)))))
