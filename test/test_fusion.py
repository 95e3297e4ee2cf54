"""Information accumulates while the load stays; a load change at a stop is found
(rozyn_estimator.online.fusion), and the online estimator publishes both."""

from __future__ import annotations

import re

import numpy as np
import pytest

from rozyn_estimator.method import Estimate
from rozyn_estimator.method.budget import Budget, Calibration
from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.online.batch import SpeedSamples
from rozyn_estimator.online.fusion import (
    DRIVE_MODEL_FLOOR,
    DRIVE_MODEL_FLOORS,
    Fusion,
    drive_model_floor,
    stops_in,
    trimmed,
)
from rozyn_estimator.online.records import NS, Job

S = 1_000_000_000  # ns per second
STD = np.array([10.0, 40.0, 0.01])  # a window's statistical std (m, I_yy, l_f)


def _estimate(params, std=STD, systematic=None) -> Estimate:
    cov = np.diag(np.asarray(std) ** 2)
    budget = None if systematic is None else Budget(cov, {"k": np.asarray(systematic)})
    return Estimate(status="ok", params=np.asarray(params, dtype=float),
                    covariance=cov if budget is None else budget.total, budget=budget)


def _windows(start_s: float, count: int, every_s: float = 60.0, length_s: float = 120.0):
    """(lo, hi) of windows every ``every_s`` of ``length_s`` from ``start_s``."""
    starts = [start_s + k * every_s for k in range(count)]
    return [(int(a * S), int((a + length_s) * S)) for a in starts]


def test_stops_are_runs_below_the_threshold_that_began_and_ended_in_the_window():
    t = np.arange(0, 100.0, 0.1)
    v = np.full(t.size, 10.0)
    v[(t >= 20) & (t < 30)] = 0.0  # a 10 s stop
    v[(t >= 50) & (t < 53)] = 0.0  # 3 s: too short
    v[t >= 95] = 0.0  # not over yet
    stops = stops_in(((t * NS).astype(np.int64), v), 2.0)
    assert stops == [(20 * S, 30 * S)]
    v[t < 10] = 0.0  # begun before the window: its start unknown
    assert stops_in(((t * NS).astype(np.int64), v), 2.0) == [(20 * S, 30 * S)]


def test_disjoint_windows_are_fused_by_their_information_and_overlapping_ones_are_not():
    fusion = Fusion()
    rng = np.random.default_rng(1)
    truth = np.array([1000.0, 2000.0, 1.2])
    own = []
    for lo, hi in _windows(0.0, 9):  # every 60 s, 120 s long: every other one is disjoint
        params = truth + STD * rng.standard_normal(3)
        own.append(params)
        out = fusion.add(_estimate(params), lo, hi, [])
    assert fusion.windows == 5  # windows 0, 2, 4, 6, 8
    np.testing.assert_allclose(out.params, np.mean(own[::2], axis=0))  # equal information: the mean
    np.testing.assert_allclose(np.sqrt(np.diag(out.covariance)), STD / np.sqrt(5))


def test_the_systematic_part_is_not_reduced():
    fusion = Fusion()
    sys = np.array([30.0, 60.0, 0.03])
    for lo, hi in _windows(0.0, 7, every_s=120.0):
        out = fusion.add(_estimate([1000.0, 2000.0, 1.2], systematic=sys), lo, hi, [])
    np.testing.assert_allclose(np.diag(out.budget.statistical), STD**2 / 7)
    np.testing.assert_allclose(np.diag(out.covariance), STD**2 / 7 + sys**2)


def test_stop_and_go_windows_keep_their_models_floor_which_fusing_does_not_reduce():
    for unsteady in (False, True):
        fusion = Fusion()
        for lo, hi in _windows(0.0, 7, every_s=120.0):
            out = fusion.add(_estimate([1000.0, 2000.0, 1.2]), lo, hi, [], unsteady=unsteady)
        floor = DRIVE_MODEL_FLOOR * np.array([1000.0, 2000.0, 0.6]) if unsteady else np.zeros(3)
        np.testing.assert_allclose(np.diag(out.covariance), STD**2 / 7 + floor**2)


def test_the_cogs_position_keeps_half_the_floor_and_the_lateral_one_a_share_of_itself():
    """l_f's measured bias on urban windows is a quarter to a half of the inertias': its floor is
    half their share. y_c's is the inertias' share of itself: a symmetric car's cannot be biased
    by the drive (mirrored, it reads mirrored), an asymmetric car's bias is odd in y_c."""
    params = np.array([1000.0, 400.0, 2000.0, 1.2, 0.0])
    np.testing.assert_allclose(drive_model_floor(FULL_PARAM_NAMES, params), [3.0, 1.2, 6.0, 0.0018, 0.0])
    params[4] = -0.03  # 3 cm right of the centreline
    assert drive_model_floor(FULL_PARAM_NAMES, params)[4] == pytest.approx(DRIVE_MODEL_FLOOR * 0.03)
    assert DRIVE_MODEL_FLOORS["cog_from_front_axle_m"] == DRIVE_MODEL_FLOOR / 2


def _drive(fusion: Fusion, before, after, stop_s: float = 400.0, count: int = 14):
    """Windows every 60 s; the vehicle stands 10 s at ``stop_s``; ``before``/``after``: the
    windows' params wholly before and from the stop on (a window over it: their mean)."""
    stop = (int(stop_s * S), int((stop_s + 10) * S))
    published = []
    for lo, hi in _windows(0.0, count):
        params = before if hi <= stop[0] else after if lo >= stop[1] else (np.add(before, after) / 2)
        published.append(fusion.add(_estimate(params), lo, hi, [stop] if lo < stop[0] < hi else []))
    return published


def test_a_load_change_at_a_stop_is_found_and_the_fusion_restarts_after_it():
    fusion = Fusion()
    loaded = [1150.0, 2047.0, 1.278]
    published = _drive(fusion, [1000.0, 2000.0, 1.2], loaded)
    assert len(fusion.changes) == 1
    assert fusion.changes[0].text().startswith("load changed at the stop at t = 400.0 s: m 1000 -> 1150 kg")
    np.testing.assert_allclose(published[-1].params, loaded)  # only the windows after the stop
    # the first window wholly after the stop (410-530 s: the update at 540 s) is where it is found
    first = next(k for k, (lo, _) in enumerate(_windows(0.0, 14)) if lo >= 410 * S)
    np.testing.assert_allclose(published[first].params, loaded)
    assert not np.allclose(published[first - 1].params, loaded)


def test_an_unchanged_load_is_not_a_change():
    rng = np.random.default_rng(2)
    changes = 0
    for _ in range(50):
        fusion = Fusion()
        base = np.array([1000.0, 2000.0, 1.2])
        stop = (int(400 * S), int(410 * S))
        for lo, hi in _windows(0.0, 14):
            fusion.add(_estimate(base + STD * rng.standard_normal(3)), lo, hi,
                       [stop] if lo < stop[0] < hi else [])
        changes += len(fusion.changes)
    assert changes == 0


def test_calibrated_values_that_vary_between_windows_are_no_load_change():
    """A full car's windows each calibrate their sensors and corners afresh, so their estimates
    scatter by the calibrated values' varying part too (its budget's ``varying``), which the test
    counts; without it the same scatter read as load changes (with the default tolerances, 19 in
    6 urban drives of the full car)."""
    rng = np.random.default_rng(3)
    base, stat_std = np.array([1000.0, 2000.0, 1.2]), np.array([2.0, 8.0, 0.002])
    var = np.array([8.0, 20.0, 0.006])
    found = {}
    for counted in (True, False):
        found[counted] = 0
        for _ in range(20):
            fusion = Fusion()
            stop = (int(400 * S), int(410 * S))
            for lo, hi in _windows(0.0, 14):
                params = base + stat_std * rng.standard_normal(3) + var * rng.standard_normal()
                budget = Budget(np.diag(stat_std**2), {"k": var}, varying={"k": var} if counted else {})
                est = Estimate(status="ok", params=params, covariance=budget.total, budget=budget)
                fusion.add(est, lo, hi, [stop] if lo < stop[0] < hi else [])
            found[counted] += len(fusion.changes)
    assert found[True] == 0 and found[False] >= 5


def test_a_window_whose_calibration_failed_is_tested_with_its_tolerances_part():
    """A window whose calibration failed (its first-order budget stands) differs from the
    calibrated windows before the stop by what their calibration moved, within the tolerances'
    part: that part is not common to both, and counts in the test. Calibrated alike, the same
    difference is a change (the systematic part common, the statistical one alone counts)."""
    calibration = (Calibration("tyre_stiffness_front_npm", 0.0, 0.05, 0.1),)
    base, systematic = np.array([1000.0, 2000.0, 1.2]), np.array([30.0, 60.0, 0.03])
    stop = (int(400 * S), int(410 * S))

    def window(params: np.ndarray, calibrated: bool) -> Estimate:
        budget = Budget(np.diag(STD**2), {"k": systematic}, calibration=calibration if calibrated else ())
        return Estimate(status="ok", params=params, covariance=budget.total, budget=budget)

    found = {}
    for after_calibrated in (False, True):
        fusion = Fusion()
        for lo, hi in _windows(0.0, 14):
            after = lo >= stop[1]
            est = window(base + 2.0 * systematic * after, calibrated=after_calibrated or not after)
            fusion.add(est, lo, hi, [stop] if lo < stop[0] < hi else [])
        found[after_calibrated] = len(fusion.changes)
    assert found == {False: 0, True: 1}


def test_a_window_holding_data_from_before_the_change_publishes_the_estimate_since():
    fusion = Fusion()
    _drive(fusion, [1000.0, 2000.0, 1.2], [1150.0, 2047.0, 1.278], count=10)  # found at 540 s
    assert fusion.changes
    restart = fusion._restart_ns
    out = fusion.add(_estimate([1100.0, 2000.0, 1.25]), restart - 5 * S, restart + 100 * S, [])
    assert out.params[0] == 1150.0  # the mixed window is not published: the estimate since the change
    fresh = Fusion()  # with nothing since a change, a window stands alone
    fresh._restart_ns = 100 * S
    assert fresh.add(_estimate([1100.0, 2000.0, 1.25]), 50 * S, 170 * S, []).params[0] == 1100.0


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_an_estimate_without_a_usable_covariance_is_published_as_it_is(bad):
    fusion = Fusion()
    est = Estimate(status="ok", params=np.array([1000.0, 2000.0, 1.2]), covariance=np.full((3, 3), bad))
    assert fusion.add(est, 0, 120 * S, []) is est


def test_online_the_load_put_in_at_a_stop_is_found_and_reported():
    """An urban drive with 150 kg put in at its stop at 332-348 s: the online estimator reports
    the change once (with the next stop, which the window that found it holds), and then
    publishes the loaded vehicle's estimate."""
    from rozyn_estimator.method import METHODS
    from rozyn_estimator.online import OnlineConfig, OnlineEstimator
    from rozyn_estimator.tolerances import Tolerances
    from rozyn_estimator.vehicle import Vehicle
    from sim_node.load_change import with_point_load
    from sim_node.road import RoadSpec
    from sim_node.simulation import SimConfig, Simulation

    vehicle = Vehicle(tolerances=Tolerances.none())
    sim = Simulation(SimConfig(vehicle=vehicle, drive_cycle_file="udds", road=RoadSpec(amplitudes="gaussian"),
                               seed=3, noise_std_mps2=0.025, load_change_kg=150.0, load_change_x_m=0.6,
                               load_change_at_s=340.0))
    block = sim.run(520.0)
    est = OnlineEstimator(vehicle, OnlineConfig(update_period_s=20.0), METHODS["likelihood"])
    stamps = (block.t_s * NS).astype(np.int64)
    speed = SpeedSamples(stamps[::10], block.speed_mps[::10].tolist(), np.arange(0, stamps.size, 10) * 2)
    channels = np.tile([0, 1], stamps.size)
    jobs = est.add_batch(channels, np.repeat(stamps, 2), block.accel_mps2.ravel(), speed=speed)
    updates = [est.compute(job) for job, _ in jobs]
    assert updates[-1].load_changes == 1
    message = est.report().message
    # the first window after it holds the next stop (428-448 s): the load may have changed at either
    assert re.search(r"load changed at one of the stops from t = 33\d\.\d s to 4[234]\d\.\d s: "
                     r"m 1\d\d\d -> 11\d\d kg", message)
    assert est.report().message.count("load changed") == 0  # said once
    truth = with_point_load(vehicle, 150.0, 0.6).sprung_mass_kg
    last = updates[-1]
    assert abs(last.params[0] - truth) < 3 * np.sqrt(last.covariance[0, 0])
    before = [u for u in updates if u.published and u.stamp_ns < 333 * S]
    assert before[-1].fused_windows >= 1 and abs(before[-1].params[0] - 1000.0) < 3 * np.sqrt(
        before[-1].covariance[0, 0])


def test_the_first_update_with_enough_driving_after_a_stop_is_cut_to_it_once():
    t = np.arange(0, 200.0, 0.1)
    stamps = (t * NS).astype(np.int64)
    v = np.full(t.size, 10.0)
    v[(t >= 50) & (t < 60)] = 0.0
    job = Job(int(200 * S), ((stamps, np.zeros(t.size)), (stamps, np.zeros(t.size))), (stamps, v))
    fusion = Fusion()
    assert fusion.test_cut(job, 150.0, 2.0) is None  # 140 s of driving after the stop: not enough
    cut = fusion.test_cut(job, 96.0, 2.0)
    assert cut == 60 * S
    after = trimmed(job, cut)
    assert after.samples[0][0][0] == 60 * S and after.speed[0][0] == 60 * S
    fusion.add(_estimate([1000.0, 2000.0, 1.2]), 0, 50 * S, [])  # a window before the stop
    fusion.add(_estimate([1000.0, 2000.0, 1.2]), 60 * S, 200 * S, [])  # its test
    assert fusion.test_cut(job, 96.0, 2.0) is None  # tested: the next windows are whole again


def test_a_change_found_over_a_later_stop_restarts_after_that_stop():
    """Stops at 400 s and 450 s, the load put in at the second: the first window wholly after the
    first stop holds the second, so the change it finds may be at either, and only the windows
    after the second are the new load's."""
    fusion = Fusion()
    empty, loaded = [1000.0, 2000.0, 1.2], [1150.0, 2047.0, 1.278]
    stops = [(int(400 * S), int(410 * S)), (int(450 * S), int(460 * S))]
    published = []
    for lo, hi in _windows(0.0, 14):
        params = loaded if lo >= stops[1][1] else empty if hi <= stops[1][0] else np.add(empty, loaded) / 2
        published.append(fusion.add(_estimate(params), lo, hi, [s for s in stops if lo < s[0] < hi]))
    assert len(fusion.changes) == 1
    assert fusion.changes[0].text().startswith("load changed at one of the stops from t = 400.0 s to 450.0 s")
    np.testing.assert_allclose(published[-1].params, loaded)  # the windows after the second stop only


def _found_over_two_stops(fusion: Fusion) -> tuple[list[Estimate], int]:
    """The load put in at the second of two stops (400 s, 450 s): the updates published, and the
    index of the one that found the change (a window after the first stop, holding both loads:
    it reads them mixed in the shares of its driving)."""
    empty, loaded = np.array([1000.0, 2000.0, 1.2]), np.array([1150.0, 2047.0, 1.278])
    stops = [(int(400 * S), int(410 * S)), (int(450 * S), int(460 * S))]
    published, found = [], -1
    for lo, hi in _windows(0.0, 14):
        driving = (hi - lo) - sum(e - s for s, e in stops if lo <= s and e <= hi)
        new = float(np.clip((hi - max(lo, stops[1][1])) / driving, 0.0, 1.0))
        params = empty + new * (loaded - empty)
        published.append(fusion.add(_estimate(params), lo, hi, [s for s in stops if lo < s[0] < hi]))
        found = len(published) - 1 if fusion.changes and found < 0 else found
    return published, found


def test_a_change_found_over_later_stops_carries_its_step_as_uncertainty():
    """The window that found a change at one of several stops may hold both loads (here 80 of its
    110 s of driving after the second stop): published, its std holds how far beyond it the new
    load lies were the change at the last stop; a change at the one stop a window lies after is
    the new load's alone and keeps the window's std."""
    published, found = _found_over_two_stops(Fusion())
    mixed = published[found]
    beyond = 1150.0 - mixed.params[0]
    assert beyond > 30.0
    assert beyond < np.sqrt(mixed.covariance[0, 0]) < beyond + STD[0]  # the new load within 1 std
    single = Fusion()
    stop = (int(400 * S), int(410 * S))
    for lo, hi in _windows(0.0, 14):
        est = single.add(_estimate([1150.0, 2047.0, 1.278] if lo >= stop[1] else [1000.0, 2000.0, 1.2]),
                         lo, hi, [stop] if lo < stop[0] < hi else [])
        if single.changes:
            break
    np.testing.assert_allclose(np.sqrt(np.diag(est.covariance)), STD)


def test_after_a_change_windows_are_cut_to_it_and_a_short_one_holds_the_estimate_since():
    """A window reaching back over the last change would read both loads: it is cut to the change
    (:meth:`Fusion.restart_cut`); cut, it may hold too little driving to estimate, and then the
    estimate that found the change stands, marked held."""
    from rozyn_estimator.online.fusion import fuse_update
    from rozyn_estimator.online.records import OK, Update

    def job(start_s: float) -> Job:  # 200 s of driving from start_s
        stamps = ((start_s + np.arange(0, 200.0, 0.1)) * NS).astype(np.int64)
        return Job(stamps[-1], ((stamps, np.zeros(stamps.size)),) * 2, (stamps, np.full(stamps.size, 10.0)))

    fusion = Fusion()
    assert fusion.restart_cut(job(0.0)) is None  # no change found: the window as it is
    _found_over_two_stops(fusion)
    assert fusion._restart_ns == 460 * S - 1
    late = job(400.0)
    assert fusion.restart_cut(late) == 460 * S
    assert trimmed(late, 460 * S).samples[0][0][0] == 460 * S
    assert fusion.restart_cut(job(500.0)) is None  # wholly after it
    short = Update(int(600 * S), OK, "window 50 % full (need 80 % of 120 s of driving)")
    held, change = fuse_update(fusion, short, trimmed(late, 460 * S), 2.0, 2.8, since_change=True)
    assert change is None and held.held and held.published
    np.testing.assert_allclose(held.params, fusion.fused.params)
    assert "since the load change, window 50 % full" in held.message
    assert fuse_update(fusion, short, late, 2.0, 2.8)[0].estimate is None  # not cut: nothing to hold
