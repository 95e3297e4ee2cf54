"""``rozyn bench``: the figures it reports (the timings themselves are replaced here: what
they measure is each figure's own business, and the full bench takes minutes)."""

from __future__ import annotations

import pytest

from rozyn_estimator.tools.bench import command as bench

KEYS = ("sim_100s_at_100hz_ms", "road_generation_ms", "update_120s_window_ms",
        "update_120s_window_no_variance_ms", "refined_update_cold_ms", "refined_update_warm_ms",
        "refined_update_warm_without_budget_ms", "glitch_update_warm_ms", "trial_100s_iso_ms",
        "study_trials_per_second", "study_refined_trials_per_second", "refined_warm_per_rozyn_update",
        "refined_cold_per_rozyn_update", "budget_overhead_pct",
        "glitch_per_clean_update", "full_refined_update_cold_ms", "full_refined_update_warm_ms",
        "full_refined_warm_per_half", "full_refined_cold_per_half", "urban_update_cold_ms",
        "urban_update_warm_ms", "urban_update_warm_slowest_ms", "urban_cold_per_constant",
        "urban_warm_per_constant", "imu_update_warm_ms",
        "imu_warm_per_accelerometers", "full_imu_update_warm_ms", "full_imu_warm_per_accelerometers",
        "peak_rss_mb", "goals")


def test_bench_reports_the_refined_studys_rate_next_to_the_others(monkeypatch):
    studies: list[tuple] = []

    def study_rate(repeats: int, method: str = "", amplitudes: str = "fixed", noise: float = 0.0) -> float:
        studies.append((repeats, method, amplitudes, noise))
        return 10.0 if method else 100.0

    def paired(fns, repeats: int) -> list[float]:
        if len(fns) == bench.URBAN_UPDATES + 1:  # the urban minute's warm updates, then the constant one
            return [*[2.0] * (bench.URBAN_UPDATES - 1), 8.0, 2.5]
        assert len(fns) == 2  # the full car's then the half car's; an IMU's then the accelerometers'
        return [3.0, 1.5]

    monkeypatch.setattr(bench, "_median_ms", lambda fn, repeats: 1.0)
    monkeypatch.setattr(bench, "_paired_ms", paired)
    monkeypatch.setattr(bench, "_study_trials_per_second", study_rate)
    out = bench.run_bench(repeats=20)
    assert tuple(out) == KEYS
    assert out["study_trials_per_second"] == 100.0 and out["study_refined_trials_per_second"] == 10.0
    assert studies == [(2, "", "fixed", 0.0), (1, "likelihood", "gaussian", 0.1)]  # the refined grid's roads
    # the full car's refined update per the half car's (issue 13: <= 3x), timed in turn with it
    assert out["full_refined_update_cold_ms"] == 3.0 and out["full_refined_cold_per_half"] == 2.0
    assert out["full_refined_warm_per_half"] == 2.0 and out["goals"]["full_refined_warm_per_half"] == 3.0
    # an urban window's update per the constant-speed one's, timed in turn with it (goal <= 1.5x)
    # warm: the mean of a minute's updates (each from the one before), and the slowest of them
    mean = (2.0 * (bench.URBAN_UPDATES - 1) + 8.0) / bench.URBAN_UPDATES
    assert out["urban_update_warm_ms"] == pytest.approx(mean, abs=1e-3)
    assert out["urban_warm_per_constant"] == pytest.approx(mean / 2.5, abs=1e-3)
    assert out["urban_update_warm_slowest_ms"] == 8.0 and out["goals"]["urban_warm_per_constant"] == 1.5
    assert out["urban_cold_per_constant"] == 2.0
    # one IMU's update per the accelerometers', either car, timed in turn with it
    assert out["imu_warm_per_accelerometers"] == 2.0 and out["full_imu_update_warm_ms"] == 3.0


def test_paired_timings_run_the_functions_in_turn_and_report_each_ones_median(monkeypatch):
    """Each repeat runs every function once, in order (a ratio then compares runs made moments
    apart on a machine whose speed drifts); each gets the median of its own times."""
    clock = [0.0]
    calls: list[str] = []

    def work(name: str, seconds: list[float]):
        def run() -> None:
            calls.append(name)
            clock[0] += seconds.pop(0)
        return run

    monkeypatch.setattr(bench.time, "perf_counter", lambda: clock[0])
    slow = work("full", [9.0, 0.003, 0.004, 0.100])  # the first is the warm-up
    fast = work("half", [9.0, 0.001, 0.002, 0.001])
    assert bench._paired_ms([slow, fast], repeats=3) == pytest.approx([4.0, 1.0])
    assert calls == ["full", "half"] * 4


def test_the_node_benchs_medians_over_all_updates_and_over_the_full_windows():
    """``rozyn bench --nodes`` reports the latency and the pipeline's time over every update
    and over the full windows' only (a drive's steady state), matched by the update's stamp."""
    from rozyn_estimator.tools.bench.nodes import _medians

    latency = {1: 50.0, 2: 40.0, 3: 30.0, 4: 20.0}
    pipeline = {1: 45.0, 3: 25.0, 4: 15.0}  # update 2's diagnostics never arrived
    assert _medians(latency, pipeline, list(latency), "") == {"update_latency_ms_median": 35.0,
                                                             "pipeline_ms_median": 25.0}
    assert _medians(latency, pipeline, [3, 4], "_full_window") == {
        "update_latency_ms_median_full_window": 25.0, "pipeline_ms_median_full_window": 20.0}


def test_the_node_bench_tells_updates_at_a_stop_from_computed_ones():
    """At a stop the node republishes the last estimate with ``held: true`` and that estimate's
    old ``pipeline_ms``: the watcher counts such an update as held, not as a computed one (its
    latency, a few ms, would flatter the urban drive's median)."""
    from types import SimpleNamespace

    from rozyn_estimator.tools.bench.nodes import _Watch

    watch = _Watch.__new__(_Watch)  # its message handling alone, without DDS
    watch.values, watch.pipeline_ms, watch.held = {}, {}, set()

    def status(**values: str) -> SimpleNamespace:
        kvs = [SimpleNamespace(key=k, value=v) for k, v in values.items()]
        return SimpleNamespace(status=[SimpleNamespace(name="rozyn: estimator_node", values=kvs)])

    watch._on_diag(status(update_stamp="35.0", pipeline_ms="61.5"))
    watch._on_diag(status(update_stamp="40.0", pipeline_ms="61.5", held="true"))
    assert watch.pipeline_ms == {"35.0": 61.5} and watch.held == {"40.0"}
