"""Property-based tests (hypothesis): no input makes the core raise or publish a made-up number.

Here: the online class fed arbitrary samples (its intake, resets, schedule and updates,
one by one and in batches), the pipeline (``estimate``) on arbitrary finite and non-finite
arrays and on real windows with glitches, and the vehicle loader on arbitrary bytes; the
bag reader on mutated bags is in ``test_fuzz_bag.py`` (helpers: ``fuzz_helpers.py``). The
properties: nothing but the narrow error types escapes, every published estimate is
finite and positive with a finite covariance, and error messages are one bounded line.

Each target runs a small, derandomized budget in the default suite (the same examples
every run) and ``FULL`` = 10 000 random examples in the slow suite
(``scripts/test -m slow -k fuzz -s`` prints how many ran and the numerical warnings seen).
Numerical warnings (numpy overflow on absurd inputs) are recorded, not raised: they are
not failures of these properties, and the slow suite lists where they come from.

The pipeline crashes the fuzz found (OverflowError in ``method/``) are reproduced at the end.
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np
import pytest
import yaml
from fuzz_helpers import FLOATS, budgets, one_line, run
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import METHODS, PipelineConfig, estimate
from rozyn_estimator.online import Level, OnlineConfig, OnlineEstimator, SpeedSamples
from rozyn_estimator.tolerances import KEYS as TOLERANCE_KEYS
from rozyn_estimator.vehicle import FIELD_UNITS, Vehicle, load_vehicle
from sim_node.simulation import SimConfig, Simulation

NS = 1_000_000_000
FAST = PipelineConfig(variance="none", refine="none")
PIPELINES = [FAST, METHODS["rozyn"], PipelineConfig()]  # Rozyn's stage alone, with its covariance, refined


# ------------------------------------------------------------------ the online class
@cache
def drive() -> np.ndarray:
    """30 s of the Table 5-1 car at 100 Hz, (n, 2): the values the streams are made of."""
    return Simulation(SimConfig(duration_s=30.0, seed=11)).run(30.0).accel_mps2


@st.composite
def streams(draw: st.DrawFn, max_lead_s: float | None = None) -> dict[str, Any]:
    """A configuration and a stream of front, rear and speed samples in arrival order, with
    faults: bad values, lost, repeated, late and far-off stamps, gaps, time jumping back.
    ``max_lead_s`` bounds how far arrival order strays from stamp order."""
    window = draw(st.sampled_from([2.0, 5.0]))
    cfg = OnlineConfig(
        window_s=window, update_period_s=draw(st.sampled_from([0.5, 1.0, 2.0])),
        min_window_fill=draw(st.sampled_from([0.05, 0.5, 0.8])),
        pair_tolerance_s=draw(st.sampled_from([0.0, 0.002])),
        rate_hz=draw(st.sampled_from([0.0, 0.0, 40.0])), max_rate_hz=draw(st.sampled_from([100.0, 30.0])),
        max_gap_s=draw(st.sampled_from([0.05, 0.5, 5.0])), jump_back_s=draw(st.sampled_from([0.01, 1.0])),
        silence_s=draw(st.sampled_from([0.05, 2.0])), speed_mps=draw(st.sampled_from([0.0, 27.8])))
    values = drive()
    parts = []
    for c, hz in enumerate(draw(st.tuples(*[st.sampled_from([100.0, 100.0, 250.0, 37.0, 3.0])] * 2))):
        n = draw(st.integers(0, min(1200, int(hz * 8))))
        t = np.round((np.arange(n) / hz + draw(st.floats(0.0, 0.05))) * NS).astype(np.int64) + 10**12
        parts.append((np.full(n, c), t, values[np.arange(n) % len(values), c].copy()))
    ch, t, v = (np.concatenate(x) for x in zip(*parts, strict=True))
    for _ in range(draw(st.integers(0, 8))):
        if not t.size:
            break
        i = draw(st.integers(0, t.size - 1))
        kind = draw(st.sampled_from(["value", "value", "stamp", "repeat", "gap", "back", "far"]))
        if kind == "value":
            v[i] = draw(FLOATS)
        elif kind == "stamp":
            t[i] += draw(st.integers(-NS, NS))
        elif kind == "repeat":
            t[i] = t[max(i - 1, 0)]
        elif kind == "gap":
            t[i:][ch[i:] == ch[i]] += draw(st.integers(0, 10 * NS))
        elif kind == "back":
            t[i:][ch[i:] == ch[i]] -= draw(st.integers(0, 10 * NS))
        else:
            t[i] = draw(st.integers(-(2**62), 2**62))
    delay = draw(st.floats(0.0, 1.0 if max_lead_s is None else max_lead_s))
    jitter = np.random.default_rng(draw(st.integers(0, 2**32 - 1))).uniform(0, delay, t.size)
    arrival = np.argsort(t + jitter * NS, kind="stable")
    speed_every = draw(st.sampled_from([0, 7, 50]))
    speeds = [draw(st.sampled_from([27.8, 27.8, 25.0])) if k % 5 else draw(FLOATS)
              for k in range(t.size // speed_every if speed_every else 0)]
    return {"cfg": cfg, "pipeline": draw(st.sampled_from(PIPELINES)), "ch": ch[arrival], "t": t[arrival],
            "v": v[arrival], "speed_every": speed_every, "speeds": speeds,
            "chunks": draw(st.lists(st.integers(1, 400), max_size=6)), "one_by_one": draw(st.booleans())}


def _chunks(n: int, sizes: list[int]) -> list[slice]:
    """``n`` arrivals cut into slices of the given sizes, repeated (one slice if none given)."""
    if not sizes:
        return [slice(0, n)]
    out, start, k = [], 0, 0
    while start < n:
        out.append(slice(start, min(n, start + sizes[k % len(sizes)])))
        start, k = start + sizes[k % len(sizes)], k + 1
    return out


def feed(s: dict[str, Any], one_by_one: bool, compute: bool = True) -> tuple[OnlineEstimator, list[Any]]:
    """Feed a stream as the node does (one by one) or as replay does (batches); the jobs and updates."""
    est = OnlineEstimator(Vehicle(), s["cfg"], s["pipeline"])
    every, speeds = s["speed_every"], s["speeds"]
    n = s["t"].size
    speed_pos = np.arange(len(speeds)) * every + every - 1 if every else np.zeros(0, np.int64)
    speed_t = s["t"][speed_pos] if speed_pos.size else np.zeros(0, np.int64)
    out: list[Any] = []

    def done(jobs: Any) -> None:
        for job in jobs:
            out.append((job, est.compute(job)) if compute else job)

    for part in _chunks(n, s["chunks"]):
        sel = (speed_pos >= part.start) & (speed_pos < part.stop)
        if one_by_one:
            for i in range(part.start, part.stop):
                done(est.add(int(s["ch"][i]), int(s["t"][i]), float(s["v"][i])))
                if every and i % every == every - 1 and i // every < len(speeds):
                    est.add_speed(int(s["t"][i]), speeds[i // every])
        else:
            order = np.arange(part.start, part.stop) * 2
            values = [speeds[k] for k in np.flatnonzero(sel)]
            speed = SpeedSamples(speed_t[sel], values, speed_pos[sel] * 2 + 1)
            done(job for job, _ in est.add_batch(s["ch"][part], s["t"][part], s["v"][part], order, speed))
        health = est.report(silent_s=(0.0, 5.0)) if part.start % 2 else est.health()
        assert isinstance(health.level, Level) and all(isinstance(x, str) for x in health.values.values())
        one_line(health.message)
    return est, out


def check_updates(pairs: list[Any]) -> None:
    for _, update in pairs:
        one_line(update.message)
        assert "internal error" not in update.message, update.message
        if update.published:
            p, cov = update.params, update.covariance
            assert np.all(np.isfinite(p)) and np.all(p > 0), p
            assert cov is None or np.all(np.isfinite(cov)), cov


@pytest.mark.parametrize("examples", budgets(25))
def test_online_class_on_arbitrary_samples(examples):
    def check(s: dict[str, Any]) -> None:
        check_updates(feed(s, s["one_by_one"])[1])

    run(examples, streams(), check, "online class")


@pytest.mark.parametrize("examples", budgets(25))
def test_batches_and_one_by_one_make_the_same_jobs(examples):
    """As the node (one by one) and as replay (batches): the same windows, whatever the faults
    (arrival order within a second of stamp order: a sensor leading the other by more than two
    windows loses its oldest samples, by design)."""
    def check(s: dict[str, Any]) -> None:
        a, jobs_a = feed(s, True, compute=False)
        b, jobs_b = feed(s, False, compute=False)
        assert [j.due_ns for j in jobs_a] == [j.due_ns for j in jobs_b]
        for x, y in zip(jobs_a, jobs_b, strict=True):
            assert x.epoch == y.epoch
            for p, q in ((x.front, y.front), (x.rear, y.rear), (x.speed, y.speed)):
                assert np.array_equal(p[0], q[0]) and np.array_equal(p[1], q[1], equal_nan=True)
        assert a.dropped == b.dropped and a.resets == b.resets
        assert a.health().values == b.health().values

    run(examples, streams(max_lead_s=1.0), check, "batches vs one by one")


# ------------------------------------------------------------------ the pipeline
@cache
def window() -> tuple[np.ndarray, Any]:
    """A 30 s window from a Gaussian road with 10 % noise, and its estimate (a warm start)."""
    accel = Simulation(SimConfig(duration_s=30.0, seed=4, noise_std_mps2=0.05)).run(30.0).accel_mps2
    return accel, estimate(accel, 100.0, Vehicle(), PipelineConfig(), 27.8)


@st.composite
def windows(draw: st.DrawFn) -> dict[str, Any]:
    """Arbitrary arrays, or a real window with glitches (single samples, runs, channels)."""
    if draw(st.booleans()):
        accel = draw(arrays(np.float64, st.tuples(st.integers(0, 600), st.just(2)), elements=FLOATS))
    else:
        accel = window()[0].copy()
        for _ in range(draw(st.integers(1, 4))):
            i, c = draw(st.integers(0, len(accel) - 1)), draw(st.integers(0, 1))
            kind = draw(st.sampled_from(["sample", "run", "scale", "constant"]))
            value = draw(FLOATS)
            if kind == "sample":
                accel[i, c] = value
            elif kind == "run":
                accel[i: i + draw(st.integers(1, 500)), c] = value
            elif kind == "scale":
                with np.errstate(all="ignore"):
                    accel[:, c] *= value
            else:
                accel[:, c] = value
    speed = draw(st.one_of(st.none(), st.floats(0.1, 150.0), FLOATS,
                           arrays(np.float64, st.just(len(accel)), elements=FLOATS)))
    warm = draw(st.one_of(st.none(), st.just(window()[1]), arrays(np.float64, st.just(3), elements=FLOATS)))
    fs = draw(st.sampled_from([100.0, 100.0, 50.0, 200.0, 7.0]))
    config = draw(st.sampled_from(PIPELINES))
    return {"accel": accel, "fs": fs, "speed": speed, "warm": warm, "config": config}


@pytest.mark.parametrize("examples", budgets(25))
def test_pipeline_on_arbitrary_arrays(examples):
    def check(w: dict[str, Any]) -> None:
        est = estimate(w["accel"], w["fs"], Vehicle(), w["config"], w["speed"], w["warm"])
        assert est.status in ("ok", "failed")
        if est.ok:
            assert np.all(np.isfinite(est.params)) and np.all(est.params > 0), est.params
            assert est.covariance is None or np.all(np.isfinite(est.covariance)), est.covariance
        else:
            assert est.params is None and est.reason

    run(examples, windows(), check, "pipeline")


# ------------------------------------------------------------------ the vehicle loader
YAML_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | FLOATS | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)


@st.composite
def vehicle_files(draw: st.DrawFn) -> bytes:
    """Arbitrary bytes, or vehicle YAML (flat or a ROS 2 parameter file) with arbitrary values, mutated."""
    if draw(st.integers(0, 3)) == 0:
        return draw(st.binary(max_size=3000))
    keys = [*FIELD_UNITS, "tolerances", "sprung_mas_kg"]
    doc = draw(st.dictionaries(st.sampled_from(keys), FLOATS | YAML_VALUES, max_size=8))
    if "tolerances" in doc and draw(st.booleans()):
        names = st.sampled_from([*TOLERANCE_KEYS, "x"])
        doc["tolerances"] = draw(st.dictionaries(names, FLOATS | YAML_VALUES, max_size=5))
    if draw(st.booleans()):
        doc = {draw(st.sampled_from(["/**", "estimator_node"])): {"ros__parameters": {"vehicle": doc}}}
    data = bytearray(yaml.safe_dump(doc, allow_unicode=draw(st.booleans())).encode())
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.integers(0, len(data)))
        data[at:at + draw(st.integers(0, 3))] = draw(st.binary(max_size=4))
    return bytes(data)


@pytest.mark.parametrize("examples", budgets(100))
def test_vehicle_loader_on_arbitrary_bytes(examples, tmp_path):
    path = tmp_path / "car.yaml"

    def check(data: bytes) -> None:
        path.write_bytes(data)
        try:
            vehicle = load_vehicle(path)
        except ConfigError as exc:
            one_line(str(exc))
            assert str(exc).startswith(str(path))
            return
        assert all(math.isfinite(getattr(vehicle, k)) for k in FIELD_UNITS)

    run(examples, vehicle_files(), check, "vehicle loader")


# ------------------------------------------------------------------ found by the fuzz, in method/
# Minimal reproductions of the pipeline crashes the fuzz found (issue 14): each raised
# OverflowError before the model's domain guard (likelihood/model.py spectrum) and the
# lag range's check (pipeline.py).
def test_a_tiny_positive_speed_is_a_status_not_an_overflow():
    accel = np.random.default_rng(0).standard_normal((1000, 2))
    est = estimate(accel, 100.0, Vehicle(), METHODS["rozyn"], speed_mps=1e-308)
    assert est.status == "failed" and "wheelbase delay" in est.reason


def test_a_slow_speed_at_a_low_rate_is_a_status_not_an_overflow():
    accel, _ = window()
    est = estimate(accel, 7.0, Vehicle(), PipelineConfig(), speed_mps=0.125)
    assert est.status == "failed" or np.all(np.isfinite(est.covariance))


def test_an_absurd_warm_start_falls_back_to_the_rozyn_start():
    accel, cold = window()
    warm = np.array([1e308, 15.0, 1e-308])  # (m, I, lf)
    est = estimate(accel, 100.0, Vehicle(), PipelineConfig(), 27.8, warm_start=warm)
    assert est.ok and est.stage == "likelihood"
    assert np.allclose(est.params, cold.params, rtol=1e-3)  # the same optimum as without it
