"""The online class: window, pairing, drops, resets and the stamp-driven schedule."""

from __future__ import annotations

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.online import NS, OK, WARN, OnlineConfig, OnlineEstimator, pair_channels
from rozyn_estimator.vehicle import Vehicle
from sim_node.simulation import SimConfig, Simulation

from conftest import TRUTH

# The schedule is under test: the Rozyn stage alone, without covariance, is enough.
FAST = PipelineConfig(variance="none", refine="none")


@pytest.fixture(scope="module")
def run():
    """200 s of the Table 5-1 car on ISO A, 100 km/h, stamps from t = 1000 s."""
    block = Simulation(SimConfig(duration_s=200.0, seed=3)).run(200.0)
    stamps = 1000 * NS + np.round(block.t_s * NS).astype(np.int64)
    return stamps, block.accel_mps2


def online(**changes) -> OnlineEstimator:
    cfg = OnlineConfig(window_s=60.0, update_period_s=5.0, speed_mps=100 / 3.6).replace(**changes)
    return OnlineEstimator(Vehicle(), cfg, FAST)


def feed(est: OnlineEstimator, stamps, accel, order="interleaved"):
    updates = []
    if order == "interleaved":
        for t, (a, b) in zip(stamps.tolist(), accel.tolist(), strict=True):
            jobs = [*est.add(0, t, a), *est.add(1, t, b)]
            updates += [est.compute(job) for job in jobs]
    else:
        n = len(stamps)
        channels = np.repeat([0, 1], n) if order == "blocks" else np.tile([1, 0], n)
        ts = np.concatenate([stamps, stamps]) if order == "blocks" else np.repeat(stamps, 2)
        vs = np.concatenate([accel[:, 0], accel[:, 1]]) if order == "blocks" else accel[:, ::-1].ravel()
        updates += [est.compute(job) for job, _ in est.add_batch(channels, ts, vs)]
    return updates


def test_schedule_window_and_estimates(run):
    stamps, accel = run
    est = online()
    updates = feed(est, stamps, accel)
    due = [u.stamp_ns for u in updates]
    assert np.all(np.diff(due) == 5 * NS) and due[0] == stamps[0] + 5 * NS
    warming = [u for u in updates if u.window_fill < 0.8]
    assert all(u.estimate is None and u.level == OK and "full" in u.message for u in warming)
    done = [u for u in updates if u.window_fill >= 0.8]
    assert len(done) >= 20 and all(u.published for u in done)
    last = done[-1]
    assert last.fs_hz == pytest.approx(100.0)
    assert last.estimate.n_samples == 6000  # 60 s at 100 Hz
    assert np.all(np.abs(last.estimate.params / TRUTH - 1) < 0.15)  # Rozyn stage, 60 s
    assert est.health().level == OK and est.health().values["mass_kg"]


def test_batches_and_arrival_order_do_not_change_the_updates(run):
    stamps, accel = run
    n = 8000
    ref = [(u.stamp_ns, None if u.estimate is None else tuple(u.estimate.params))
           for u in feed(online(), stamps[:n], accel[:n])]
    for order in ("blocks", "swapped"):
        got = [(u.stamp_ns, None if u.estimate is None else tuple(u.estimate.params))
               for u in feed(online(), stamps[:n], accel[:n], order)]
        assert got == ref, order


def test_non_finite_duplicate_and_out_of_order_samples_are_dropped(run):
    stamps, accel = run
    est = online()
    bad = accel[:3000].copy()
    bad[100, 0] = np.nan
    bad[200, 1] = np.inf
    for t, (a, b) in zip(stamps[:3000].tolist(), bad.tolist(), strict=True):
        est.add(0, t, a)
        est.add(1, t, b)
        if t == stamps[500]:
            est.add(0, t, a)  # duplicate
            est.add(1, t - 3 * NS // 100, b)  # 30 ms back: out of order
    assert est.dropped["front: non-finite value"] == 1
    assert est.dropped["rear: non-finite value"] == 1
    assert est.dropped["front: duplicate stamp"] == 1
    assert est.dropped["rear: out-of-order stamp"] == 1
    assert est.resets == 0
    assert est.health() == est.health()  # looking changes nothing
    h = est.report()
    assert h.level == WARN and "lost 4 samples" in h.message
    assert h.values["dropped_total"] == "4" and h.values["dropped (rear: out-of-order stamp)"] == "1"
    assert est.report().level == OK  # reported once


def test_samples_lost_on_the_way_are_counted(run):
    stamps, accel = run
    keep = np.ones(len(stamps), bool)
    keep[[300, 301, 302, 900]] = False  # 4 front samples never arrive
    one, batch = online(), online()
    for t, a, b, k in zip(stamps[:2000].tolist(), accel[:2000, 0], accel[:2000, 1], keep, strict=False):
        if k:
            one.add(0, t, a)
        one.add(1, t, b)
    k = keep[:2000]
    batch.add_batch(np.zeros(k.sum(), int), stamps[:2000][k], accel[:2000, 0][k])
    batch.add_batch(np.ones(2000, int), stamps[:2000], accel[:2000, 1])
    for est in (one, batch):
        h = est.health()
        assert (h.values["missing_front"], h.values["missing_rear"]) == ("4", "0")
        assert h.level == WARN and "lost 4 samples" in h.message


def test_batch_with_anomalies_equals_one_by_one(run):
    stamps, accel = run
    t = np.repeat(stamps[:2000], 2)
    c = np.tile([0, 1], 2000)
    v = accel[:2000].ravel().copy()
    v[10] = np.nan
    t[501] = t[499]  # rear duplicate
    t[2000:] += 3 * NS  # a gap on both: reset
    one, batch = online(), online()
    one_jobs = []
    for ci, ti, vi in zip(c.tolist(), t.tolist(), v.tolist(), strict=True):
        one_jobs += [(job, len(one_jobs)) for job in one.add(ci, ti, vi)]
    batch_jobs = batch.add_batch(c, t, v)
    assert one.dropped == batch.dropped and one.resets == batch.resets == 1
    assert [j.due_ns for j, _ in one_jobs] == [j.due_ns for j, _ in batch_jobs]


def test_gap_and_time_jumping_back_reset_the_window(run):
    stamps, accel = run
    est = online()
    feed(est, stamps[:3000], accel[:3000])
    feed(est, stamps[3000:6000] + 2 * NS, accel[3000:6000])  # a 2 s gap
    assert est.resets == 1
    assert any("gap of 2.010 s" in msg for _, msg in est.events)
    feed(est, stamps[:3000], accel[:3000])  # bag loop: back to the start
    assert est.resets == 2
    assert any("time jumped back" in msg for _, msg in est.events)
    h = est.health()
    assert h.values["window_resets"] == "2"
    assert h.values["samples_front"] == "9000"  # counted across resets


def test_one_silent_sensor_gives_no_estimate_and_a_warning(run):
    stamps, accel = run
    est = online()
    jobs = []
    for t, a in zip(stamps[:8000].tolist(), accel[:8000, 0].tolist(), strict=True):
        jobs += est.add(0, t, a)
    assert jobs == []
    h = est.health()
    assert h.level == WARN and "waiting for rear" in h.message
    est.add(1, int(stamps[7000]), 9.8)  # the rear speaks once, then lags by 10 s
    h = est.health()
    assert h.level == WARN and "rear: 10.0 s behind" in h.message
    h = est.health(silent_s=(0.1, 4.0))
    assert h.level == WARN and h.message == "waiting for rear: no message for 4.0 s"


def test_rate_mismatch_and_offsets_are_resampled(run):
    stamps, accel = run
    est = online()
    fine = Simulation(SimConfig(duration_s=200.0, seed=3, rate_hz=400.0)).run(200.0)
    fine_t = 1000 * NS + np.round(fine.t_s * NS).astype(np.int64) + 1_300_000  # 1.3 ms late
    channels = np.r_[np.zeros(len(stamps), int), np.ones(len(fine_t), int)]
    t, v = np.r_[stamps, fine_t], np.r_[accel[:, 0], fine.accel_mps2[:, 1]]
    arrival = np.argsort(t, kind="stable")  # in stamp order, as they would arrive
    jobs = est.add_batch(channels[arrival], t[arrival], v[arrival])
    updates = [u for u in (est.compute(job) for job, _ in jobs) if u.published]
    assert updates and updates[-1].fs_hz == pytest.approx(100.0)
    aligned = [u for u in feed(online(), stamps, accel) if u.published]
    assert [u.stamp_ns for u in updates] == [u.stamp_ns for u in aligned]
    # the same car seen through a 400 Hz sensor 1.3 ms late: the same estimate within 2 %
    assert np.allclose(updates[-1].estimate.params, aligned[-1].estimate.params, rtol=0.02)


def test_pairing_of_aligned_and_offset_channels():
    t = np.arange(0, 1000) * 10_000_000
    v = np.sin(t / NS)
    cfg = OnlineConfig()
    grid, y, fs = pair_channels((t, v), (t, 2 * v), cfg)
    assert np.array_equal(grid, t) and fs == pytest.approx(100.0) and np.allclose(y[:, 1], 2 * v)
    grid, y, fs = pair_channels((t, v), (t + 5_000_000, v), cfg)  # 5 ms apart: resampled
    assert np.all(np.diff(grid) == 10_000_000)
    assert np.allclose(y[:, 0], np.sin(grid / NS), atol=1e-4)
    assert pair_channels((t[:500], v[:500]), (t[600:], v[600:]), cfg) == \
        "front and rear samples do not overlap in time"


def test_speed_varying_beyond_the_set_limit_is_not_used(run):
    stamps, accel = run
    est = online(speed_mps=0.0, max_speed_variation=0.1)
    updates = []
    for k, (t, (a, b)) in enumerate(zip(stamps.tolist(), accel.tolist(), strict=True)):
        if k % 100 == 0:
            est.add_speed(t, 25.0 + 5.0 * (t - stamps[0]) / (60 * NS))  # +18 % per window
        updates += [est.compute(job) for job in (*est.add(0, t, a), *est.add(1, t, b))]
    updates = [u for u in updates if u.window_fill >= 0.8]
    assert updates and all(not u.published and "speed varied" in u.message for u in updates)


def _with_speed(run, speed_at, every: int = 10):
    """The run fed with a speed sample every ``every`` samples, ``speed_at(k)`` its value (None:
    none sent); the updates whose window is 80 % full, and the estimator."""
    stamps, accel = run
    est = online(speed_mps=0.0)
    updates = []
    for k, (t, (a, b)) in enumerate(zip(stamps.tolist(), accel.tolist(), strict=True)):
        if k % every == 0 and (v := speed_at(k)) is not None:
            est.add_speed(t, v)
        updates += [est.compute(job) for job in (*est.add(0, t, a), *est.add(1, t, b))]
    return [u for u in updates if u.window_fill >= 0.8], est


def test_a_speed_topic_that_falls_silent_is_not_trusted(run):
    """Speed at 10 Hz for the first 30 s, then none: every window from then on has a stretch
    without a speed (longer than speed_silence_s) and is not used; sent throughout, all are."""
    steady = 100 / 3.6
    updates, _ = _with_speed(run, lambda k: steady)
    assert len(updates) >= 20 and all(u.published for u in updates)
    updates, _ = _with_speed(run, lambda k: steady if k < 3000 else None)
    assert len(updates) >= 20
    for u in updates:
        assert not u.published and u.level == WARN and "speed topic was silent" in u.message, u.message
    silent = [float(u.message.split("silent for ")[1].split(" s")[0]) for u in updates]
    last_speed_ns = run[0][2990]  # the last one sent
    since = np.array([(u.stamp_ns - last_speed_ns) / NS for u in updates])
    np.testing.assert_allclose(silent, np.minimum(since, 60.0), atol=0.06)  # at most the window


def test_a_speed_gap_shorter_than_the_limit_is_bridged(run):
    """A 1.5 s gap in a 10 Hz speed topic is below the 2 s limit: the windows are used."""
    updates, _ = _with_speed(run, lambda k: None if 5000 <= k < 5150 else 100 / 3.6)
    assert len(updates) >= 20 and all(u.published for u in updates)


@pytest.mark.parametrize(("value", "reason"), [
    (1e9, "speed: outside 0-150 m/s"), (-3.0, "speed: outside 0-150 m/s"),
    (float("nan"), "speed: not a number")])
def test_speeds_outside_the_physical_range_are_dropped_and_counted(run, value, reason):
    """A speed topic reading 1e9 m/s gave a made-up mass (23 177 ± 8 601 kg): now every such
    sample is dropped and counted, and the windows it should have timed are not used."""
    updates, est = _with_speed(run, lambda k: value)
    assert est.dropped[reason] == 2000  # 200 s at 10 Hz
    assert len(updates) >= 20 and all(not u.published and "no valid speed" in u.message for u in updates)


@pytest.mark.parametrize(
    ("changes", "name"),
    [({"window_s": -1.0}, "window_s"), ({"update_period_s": 200.0}, "update_period_s"),
     ({"min_window_fill": 0.0}, "min_window_fill"), ({"max_gap_s": 0.0}, "max_gap_s")],
)
def test_invalid_config_names_the_parameter(changes, name):
    with pytest.raises(ConfigError, match=name):
        OnlineConfig(**changes)


def test_fast_sensors_are_decimated_to_max_rate():
    fast = Simulation(SimConfig(duration_s=130.0, seed=4, rate_hz=1000.0)).run(130.0)
    slow = Simulation(SimConfig(duration_s=130.0, seed=4, rate_hz=100.0)).run(130.0)
    results = []
    for block in (fast, slow):
        est = online()
        t = np.round(block.t_s * NS).astype(np.int64)
        jobs = [job for c in (0, 1)
                for job, _ in est.add_batch(np.full(t.size, c), t, block.accel_mps2[:, c])]
        results.append([u for u in map(est.compute, jobs) if u.published][-1])
    assert results[0].fs_hz == pytest.approx(100.0) and results[0].estimate.n_samples == 6000
    # the same car, the same road: the 1 kHz sensors decimated agree with 100 Hz ones
    assert np.allclose(results[0].estimate.params, results[1].estimate.params, rtol=0.03)


@pytest.mark.parametrize(("native_hz", "tol"), [(1000.0, 1e-4), (400.0, 1e-4), (250.0, 5e-3)])
def test_fast_channels_are_low_passed_onto_the_grid(native_hz, tol):
    """Integer ratios take the polyphase path (1 kHz, 400 Hz), others the filter-and-interpolate
    one (250 Hz): both keep a 3 Hz and a 7 Hz tone and remove a 60 Hz one (away from the
    window's ends, where, as with ``filtfilt``, the padding sees the interferer). Linear
    interpolation between 250 Hz samples costs ~4e-3 on the 7 Hz tone."""
    n = round(120 * native_hz)
    t = 10**12 + np.round(np.arange(n) * NS / native_hz).astype(np.int64)
    ts = t / NS
    noise = np.sin(2 * np.pi * 60.0 * ts)  # above the 100 Hz grid's Nyquist: must not alias in
    front = np.sin(2 * np.pi * 3.0 * ts) + 9.81 + noise
    rear = np.cos(2 * np.pi * 7.0 * ts) + noise
    grid, y, fs = pair_channels((t, front), (t, rear), OnlineConfig())
    g = grid / NS
    assert fs == pytest.approx(100.0) and np.all(np.diff(grid) == 10_000_000)
    assert g[-1] == pytest.approx(ts[-1]) and g[0] - ts[0] < 0.011
    inner = slice(20, -20)  # 0.2 s from either end
    assert np.abs(y[inner, 0] - np.sin(2 * np.pi * 3.0 * g[inner]) - 9.81).max() < tol
    assert np.abs(y[inner, 1] - np.cos(2 * np.pi * 7.0 * g[inner])).max() < tol
    assert np.all(np.isfinite(y)) and np.abs(y[:, 1]).max() < 2.5
