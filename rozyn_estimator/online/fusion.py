"""Information accumulates while the load stays; a load change at a stop is found and restarts it.

Each update estimates one window. While the load is the same, the windows since the last change
all measure the same vehicle, so the published estimate fuses them: the information-weighted
mean of their estimates, ``P = Σ S_i⁻¹``, ``θ = P⁻¹ Σ S_i⁻¹ θ_i``, with ``S_i`` a window's
*statistical* covariance (its budget's; the exact vehicle's whole covariance). Overlapping
windows share data, so only disjoint ones are fused: each window joins the best chain of
disjoint windows that ended before it began (the one with the most windows, then the latest),
which with windows every half window length is every other one. The tolerances' systematic
part is common to every window and is not reduced: the published covariance is the fused
statistical one plus the newest window's systematic one.

A stop of at least :data:`MIN_STOP_S` (the speed below the driving threshold) is where the load
may change. Once a window lies wholly after such a stop, it is tested against the fused
estimate of the windows wholly before it (two disjoint data sets: only their statistical parts
count, the systematic part is common to both where both were calibrated alike, else the
window's counts too: :func:`_not_common`): ``χ² = dᵀ (S_after + P_before⁻¹)⁻¹ d`` on ``k``
degrees of freedom. So that this comes soon, the first update with a window's worth of
driving after a stop (``min_window_fill`` of ``window_s``) estimates from the driving after it
alone (:meth:`Fusion.test_cut`), a probe that is fused only where it found a change (a window
that begins as the vehicle pulls away reads the body a little less well: fused, such windows
took the half hour's I_yy from -0.5 to -0.9 %). At ``p <`` :data:`CHANGE_P` the load changed
at that stop — or, where the window holds later stops (in town it usually does), at one of
them: the window reads the old load up to the one where it changed. The fusion restarts from
the driving after the last stop the window holds, the event is reported (``load changed at the
stop at t = …: m 1000 → 1150 kg``, or ``at one of the stops from t = … to …``) and counted.
The windows after it are cut to that driving (:meth:`Fusion.restart_cut`: a window reaching
back over the change would read both loads); while a cut one holds too little driving to
estimate, the window that found the change stands, marked held. Where that window held later
stops it may hold both loads, and the new load then lies beyond it: its covariance holds how
far, were the change at the last stop (``load_change`` in the budget, :func:`_mixed_spread`;
an urban drive's +150 kg: the mass ±400-650 kg until 96 s of driving after the last stop).
Until the test the windows reaching over the stop are fused as any other (they hold both
loads, which only the test can tell).

What fusing cannot reduce: a varying drive's model (the mixture of local spectra,
:mod:`~rozyn_estimator.method.likelihood.road_input`) is an approximation, which on urban windows
read I_yy up to 0.5 % low (the half car's with one IMU 0.4 %, with two accelerometers 0.1 %; the
full car's I_xx 0.7 %; docs/method.md, "Real drives"). One window's spread is 4-8 times that,
but a half hour's fused estimate is as precise as the bias is large (cut square, the half car's
coverage of I_yy fell to 88 %). So the
published covariance holds :data:`DRIVE_MODEL_FLOOR` of each value as a systematic part
(``drive_model`` in the budget) in the share of the fused windows that were stop-and-go
(masked in part: :func:`~rozyn_estimator.method.likelihood.road_input.unsteady`); steady
windows, such as a highway's, carry none. l_f has half that floor
(:data:`DRIVE_MODEL_FLOORS`): its bias on urban windows measured 0.09-0.15 % in every
configuration (the half car −0.09 ± 0.04 % over 432 windows, with one IMU −0.12 ± 0.04, the
full car −0.15 ± 0.17), a quarter to a half of the inertias' (I_yy up to 0.4 %). The lateral
CoG's floor is the inertias' share of itself: the model takes the road as alike on both
tracks, so a car mirrored reads its y_c mirrored, and no drive can bias a symmetric car's
(measured +0.3 ± 1.8 mm on one window, +0.2 ± 0.5 mm after four urban half hours); an
asymmetric car's bias is odd in y_c. Over eight urban half hours of the symmetric full car its
statistical std alone covered the fused y_c in 97.7 % of the updates after 10 minutes (rms
z 0.83). At 0.3 % (3 mm) l_f's floor, not its data, would set its std after a half hour.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from rozyn_estimator.method import Estimate
from rozyn_estimator.method.likelihood.road_input import unsteady
from rozyn_estimator.online.driving import driving_time_s
from rozyn_estimator.online.records import NS, Job, Update

MIN_STOP_S = 5.0  # a stop this long may change the load
# the test's level per stop: an urban half hour has about 20 tests, and the windows' tails are
# heavier than a χ²'s (at 1e-4, 2 of 20 urban drives found a change where there was none)
CHANGE_P = 1e-6
# the least share of a window's driving after its last stop taken for the new load's: a change
# found in a smaller share would be more than four times the step found (a load of 600 kg where
# it found 150); a share of 5 % published the mass ±4400 kg
_LEAST_SHARE = 0.25
MAX_CHAINS = 512  # chains kept since the last change (each an update's; the oldest go first)
DRIVE_MODEL_FLOOR = 0.003  # the varying drive's model: share of each value
# the CoG's longitudinal position, where its own share is smaller (module docstring)
DRIVE_MODEL_FLOORS = {"cog_from_front_axle_m": 0.0015}


@dataclass(frozen=True)
class Chain:
    """Disjoint windows fused: their summed information and information-weighted estimates."""

    lo_ns: int  # the newest window's first sample
    hi_ns: int  # the newest window's last sample
    info: np.ndarray  # (k, k) Σ S_i⁻¹
    weighted: np.ndarray  # (k,) Σ S_i⁻¹ θ_i
    windows: int
    unsteady: int = 0  # of them stop-and-go windows (masked in part)
    calibrated: int = 0  # of them windows whose data calibrated the tolerances' values

    @property
    def covariance(self) -> np.ndarray:
        return np.linalg.inv(self.info)

    @property
    def mean(self) -> np.ndarray:
        return np.linalg.solve(self.info, self.weighted)


@dataclass(frozen=True)
class LoadChange:
    """A detected change: the stop's start [ns], the mass before and after [kg], the test's p; where
    the window tested held later stops, the last one's start (the load changed at one of them)."""

    stop_ns: int
    mass_before_kg: float
    mass_after_kg: float
    p_value: float
    last_stop_ns: int | None = None

    def text(self) -> str:
        p = f"p = {self.p_value:.1g}" if self.p_value >= 1e-9 else "p < 1e-9"
        last = self.stop_ns if self.last_stop_ns is None else self.last_stop_ns
        where = f"the stop at t = {self.stop_ns / NS:.1f} s" if last == self.stop_ns else \
            f"one of the stops from t = {self.stop_ns / NS:.1f} s to {last / NS:.1f} s"
        return f"load changed at {where}: m {self.mass_before_kg:.0f} -> {self.mass_after_kg:.0f} kg ({p})"


def stops_in(speed: tuple[np.ndarray, np.ndarray], threshold_mps: float,
             min_stop_s: float = MIN_STOP_S) -> list[tuple[int, int]]:
    """The complete stops in a window's speed samples: (first standing, first driving again) [ns]
    of each run below ``threshold_mps`` lasting at least ``min_stop_s``."""
    t, v = speed
    if t.size < 2:
        return []
    standing = np.r_[False, v < threshold_mps, False]
    edges = np.flatnonzero(np.diff(standing.astype(np.int8)))
    out = []
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        if end < t.size and start > 0 and (t[end] - t[start]) >= min_stop_s * NS:  # ended, and began here
            out.append((int(t[start]), int(t[end])))
    return out


class Fusion:
    """The windows' estimates fused since the last load change, and the changes found."""

    def __init__(self) -> None:
        self.reset()
        self.changes: list[LoadChange] = []  # every change found, kept across resets

    def reset(self) -> None:
        """Forget the windows (a window reset: the data before it are another run's)."""
        self._chains: list[Chain] = []
        self._stops: dict[int, int] = {}  # stop start -> end [ns], not yet tested
        self._tested: set[int] = set()  # the starts of the stops tested (later windows see them too)
        self._restart_ns = -1  # windows must begin after this to be fused
        self._spread: np.ndarray | None = None  # (k,) the last change's step where it may be mixed
        self._fused: Estimate | None = None
        self._windows = 0

    @property
    def fused(self) -> Estimate | None:
        """The last published fused estimate (what a stop holds)."""
        return self._fused

    @property
    def windows(self) -> int:
        """How many windows the last published estimate fused (0: none yet)."""
        return self._windows

    def add(self, est: Estimate, lo_ns: int, hi_ns: int, stops: list[tuple[int, int]],
            unsteady: bool = False, probe: bool = False) -> Estimate:
        """The estimate to publish for a window ``[lo_ns, hi_ns]`` whose own estimate is ``est``,
        the complete stops in it given, ``unsteady`` a stop-and-go window; a ``probe`` (cut to
        a stop's end: :meth:`test_cut`) is fused only where it found a change (see the module)."""
        self._register(stops)
        stat = est.statistical_covariance
        if stat is None or est.params is None or not np.all(np.isfinite(stat)):
            return est
        try:
            info = np.linalg.inv(stat)
        except np.linalg.LinAlgError:
            return est
        found = len(self.changes)
        self._test_stops(est, stat, lo_ns, hi_ns)
        if probe and len(self.changes) == found and self._fused is not None:
            return self._fused  # the load stays: the fused windows stand (a probe starts at pulling away)
        if lo_ns <= self._restart_ns:  # it holds data from before the last change
            if self._chains and self._fused is not None:
                return self._fused  # the estimate since the change stands
            self._fused, self._windows = _widened(est, self._spread), 1
            return self._fused
        before = self._best(lo_ns)
        own = Chain(lo_ns, hi_ns, info, info @ est.params, 1, int(unsteady), int(_calibrated(est)))
        chain = own if before is None else Chain(
            lo_ns, hi_ns, before.info + info, before.weighted + own.weighted, before.windows + 1,
            before.unsteady + own.unsteady, before.calibrated + own.calibrated)
        self._chains = [*self._chains, chain][-MAX_CHAINS:]
        self._fused, self._windows = _published(est, chain), chain.windows
        return self._fused

    def test_cut(self, job: Job, min_driving_s: float, driving_mps: float) -> int | None:
        """Where to start ``job``'s window so that it lies wholly after a stop not yet tested, with
        at least ``min_driving_s`` of driving after it (the oldest such stop's end [ns]; None:
        the window as it is)."""
        self._register(stops_in(job.speed, driving_mps))
        lo = first_stamp_ns(job)
        if lo is None:
            return None
        for start, end in sorted(self._stops.items()):
            if start > lo and end <= job.due_ns and \
                    driving_time_s(job.speed, end, job.due_ns, driving_mps) >= min_driving_s:
                return end
        return None

    def restart_cut(self, job: Job) -> int | None:
        """Where to start ``job``'s window so that it holds only the driving since the last load
        change found (None: it does, or none was found): a window reaching back over the change
        would read both loads."""
        lo = first_stamp_ns(job)
        if self._restart_ns < 0 or lo is None or lo > self._restart_ns:
            return None
        return self._restart_ns + 1

    def _register(self, stops: list[tuple[int, int]]) -> None:
        for start, end in stops:
            if start > self._restart_ns and start not in self._stops and start not in self._tested:
                self._stops[start] = end

    def _best(self, before_ns: int) -> Chain | None:
        """The chain with the most windows (then the latest) that ended by ``before_ns``."""
        done = [c for c in self._chains if c.hi_ns <= before_ns]
        return max(done, key=lambda c: (c.windows, c.hi_ns)) if done else None

    def _test_stops(self, est: Estimate, stat: np.ndarray, lo_ns: int, hi_ns: int) -> None:
        """Test each stop this window lies wholly after; restart where the load changed."""
        for start in sorted(s for s, end in self._stops.items() if end <= lo_ns):
            if start not in self._stops:  # in a window that found a change (below)
                continue
            end = self._stops.pop(start)
            self._tested.add(start)
            before = self._best(start)
            if before is None or est.params is None:
                continue
            d = est.params - before.mean
            # the calibrated values vary too: this window's afresh, the fused ones' averaged down
            share = 1.0 + 1.0 / before.windows
            varying = 0.0 if est.budget is None else est.budget.varying_covariance * share
            cov = stat + varying + _not_common(est, stat, before) + before.covariance
            try:
                z2 = float(d @ np.linalg.solve(cov, d))
            except np.linalg.LinAlgError:
                continue
            p = float(chi2.sf(z2, d.size))
            if p < CHANGE_P:
                # stops within the window: the load may have changed at one of them instead, so
                # only the driving after the last is surely the new load's
                inside = sorted((s, e) for s, e in self._stops.items() if s >= lo_ns)
                last, end = inside[-1] if inside else (start, end)
                self.changes.append(LoadChange(start, float(before.mean[0]), float(est.params[0]), p, last))
                self._tested.update(s for s, _ in inside)
                self._spread = _mixed_spread(d, lo_ns, hi_ns, inside) if last != start else None
                self._restart_ns = end - 1
                self._chains = []
                self._stops = {s: e for s, e in self._stops.items() if s > last}


def _mixed_spread(step: np.ndarray, lo_ns: int, hi_ns: int, inside: list[tuple[int, int]]) -> np.ndarray:
    """(k,) how far beyond a window ``[lo_ns, hi_ns]`` that found the change ``step`` the new load's
    values may lie when the load changed at the last of the stops ``inside`` it: the window then
    reads the new load in the share ``f`` of its driving after that stop, and as a mixture its
    step is ``f`` of the whole, which lies ``step (1/f - 1)`` beyond it."""
    driving = (hi_ns - lo_ns) - sum(end - start for start, end in inside)
    share = (hi_ns - inside[-1][1]) / driving if driving > 0 else 0.0
    return step * (1.0 / max(share, _LEAST_SHARE) - 1.0)


def _widened(est: Estimate, spread: np.ndarray | None) -> Estimate:
    """``est`` with ``spread`` (k,) as a systematic part (``load_change`` in the budget): a window
    that found a change at one of several stops may hold both loads (:func:`_mixed_spread`)."""
    if spread is None:
        return est
    if est.budget is None:
        return dataclasses.replace(est, covariance=est.covariance + np.outer(spread, spread))
    contributions = {**est.budget.contributions, "load_change": spread}
    budget = dataclasses.replace(est.budget, contributions=contributions)
    return dataclasses.replace(est, covariance=budget.total, budget=budget)


def _calibrated(est: Estimate) -> bool:
    """Whether the window's data calibrated the tolerances' values (not: none to calibrate,
    calibration off, or failed and the first-order budget stands)."""
    return est.budget is not None and bool(est.budget.calibration)


def _not_common(est: Estimate, stat: np.ndarray, before: Chain) -> np.ndarray | float:
    """The window's systematic covariance where the windows before were not calibrated as it was
    (0: calibrated alike, the systematic part common to both): a calibration moves an estimate
    within its tolerances' part, so an uncalibrated window (its calibration failed) differs from
    calibrated ones by up to that (two urban drives of the full car found a load change where
    there was none, at 1.0 and 1.4 of the window's whole std)."""
    alike = before.calibrated in (0, before.windows) and (before.calibrated > 0) == _calibrated(est)
    return 0.0 if alike or est.covariance is None else est.covariance - stat


def _published(est: Estimate, chain: Chain) -> Estimate:
    """``est`` with the chain's fused estimate and statistical covariance, its own systematic part
    and the varying drive's model's (see the module's docstring)."""
    if chain.windows == 1:
        return est
    params, fused_stat = chain.mean, chain.covariance
    floor = drive_model_floor(est.names, params) * (chain.unsteady / chain.windows)
    if est.budget is None:
        return dataclasses.replace(est, params=params, covariance=fused_stat + np.diag(floor**2))
    budget = dataclasses.replace(est.budget, statistical=fused_stat,
                                 contributions={**est.budget.contributions, "drive_model": floor})
    return dataclasses.replace(est, params=params, covariance=budget.total, budget=budget)


def drive_model_floor(names: tuple[str, ...], params: np.ndarray) -> np.ndarray:
    """(k,) the varying drive's model's std of each of ``params`` (``names``' order) over a window
    that is all stop-and-go (see the module's docstring)."""
    shares = np.array([DRIVE_MODEL_FLOORS.get(name, DRIVE_MODEL_FLOOR) for name in names])
    return shares * np.abs(np.asarray(params, dtype=float))


def first_stamp_ns(job: Job) -> int | None:
    """The window's first sample's stamp [ns] (None: no samples)."""
    return min((int(stamps[0]) for stamps, _ in job.samples if stamps.size), default=None)


def trimmed(job: Job, from_ns: int) -> Job:
    """``job`` with its samples (and speeds) from ``from_ns`` on."""
    samples = tuple((t[t >= from_ns], v[t >= from_ns]) for t, v in job.samples)
    t, v = job.speed
    return dataclasses.replace(job, samples=samples, speed=(t[t >= from_ns], v[t >= from_ns]))


def _stop_and_go(speed: tuple[np.ndarray, np.ndarray], wheelbase_m: float) -> bool:
    """Whether the window's speed samples make it a stop-and-go window (masked in part)."""
    t, v = speed
    if t.size < 2:
        return False
    fs = NS / float(np.median(np.diff(t)))
    return unsteady(wheelbase_m, v, fs)


def fuse_update(fusion: Fusion, update: Update, job: Job, driving_mps: float, wheelbase_m: float,
                probe: bool = False, since_change: bool = False) -> tuple[Update, str | None]:
    """(the update to publish, the text of a load change it found or None): a published window's
    estimate fused; a held one's the last fused estimate; a window cut to the last load change
    (``since_change``) that holds too little driving yet holds the estimate since the change."""
    short = since_change and update.estimate is None  # cut to the change, too little driving
    if (update.held or short) and fusion.fused is not None:
        message = f"held: since the load change, {update.message}; the estimate that found it stands" \
            if short else update.message
        return dataclasses.replace(update, estimate=fusion.fused, held=True, message=message,
                                   fused_windows=fusion.windows, load_changes=len(fusion.changes)), None
    if not update.published or update.estimate is None:
        return update, None
    lo = first_stamp_ns(job)
    found = len(fusion.changes)
    est = fusion.add(update.estimate, update.stamp_ns if lo is None else lo, update.stamp_ns,
                     stops_in(job.speed, driving_mps), _stop_and_go(job.speed, wheelbase_m), probe)
    change = fusion.changes[-1].text() if len(fusion.changes) > found else None
    return dataclasses.replace(update, estimate=est, fused_windows=fusion.windows,
                               load_changes=len(fusion.changes)), change


__all__ = ["CHANGE_P", "DRIVE_MODEL_FLOOR", "DRIVE_MODEL_FLOORS", "MIN_STOP_S", "Chain", "Fusion",
           "LoadChange", "drive_model_floor", "fuse_update", "stops_in", "trimmed"]
