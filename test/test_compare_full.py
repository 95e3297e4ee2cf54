"""``rozyn compare --model full``: the full car's methods side by side, its summaries and its
acceptance and mismatch suites (the 100-seed runs are slow-marked)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rozyn_estimator.method.config import FULL_PARAM_NAMES
from rozyn_estimator.method.pipeline import Estimate
from rozyn_estimator.tools.cars import FULL
from rozyn_estimator.tools.cli import main
from rozyn_estimator.tools.compare.compare import bar_failures, compare
from rozyn_estimator.tools.compare.suites import Bars, suite
from rozyn_estimator.tools.trial.run import TrialResult
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.tools.trial.summary import summarise

TRUTH = np.array([1000.0, 400.0, 2000.0, 1.2, 0.0])


def _result(params: list[float], std: list[float]) -> TrialResult:
    est = Estimate(status="ok", params=np.array(params), covariance=np.diag(np.square(std)),
                   names=FULL_PARAM_NAMES, elapsed_ms=5.0)
    return TrialResult(1, est, TRUTH, 0.0, "full")


def _cases(name: str, preset: str = "table5-1") -> list:
    return suite(name, TrialSpec(vehicle=FULL.presets[preset]))


def test_the_summary_counts_bias_coverage_and_failures():
    failed = Estimate(status="failed", reason="no modes", names=FULL_PARAM_NAMES)
    results = [_result([1010.0, 400.0, 2000.0, 1.2, 0.004], [10.0, 1.0, 1.0, 0.01, 0.001]),
               _result([1000.0, 410.0, 2000.0, 1.2, 0.002], [10.0, 1.0, 1.0, 0.01, 0.001]),
               TrialResult(3, failed, TRUTH, 0.0, "full")]
    s = summarise(results)
    assert s.n == 3 and s.failures == 1
    assert s.bias_pct[0] == pytest.approx(0.5) and s.bias_pct[1] == pytest.approx(1.25)
    assert s.bias[4] == pytest.approx(0.003) and np.isnan(s.bias_pct[4])  # metres: no per cent of 0
    assert s.coverage_95.tolist() == [1.0, 0.5, 1.0, 1.0, 0.0]
    missed = bar_failures(s, Bars(bias_pct=0.5), FULL)
    assert "failures 1/3" in missed and any(m.startswith("bias I_xx +1.25 %") for m in missed)
    assert any(m.startswith("coverage y_c") for m in missed)
    assert not any(m.startswith("bias I_yy") for m in missed)
    assert "coverage I_yy 1.00" in missed  # 100 %: too wide is missed too
    assert "bias y_c" not in " ".join(missed)  # 3 mm: within the lateral bar of 5 mm
    assert "bias y_c +6.00 mm" in bar_failures(summarise([_result([1000.0, 400.0, 2000.0, 1.2, 0.006],
                                                                  [1.0] * 5)] * 2), Bars(), FULL)


def test_the_acceptance_cases_are_on_the_exact_vehicle():
    cases = _cases("acceptance", "second")
    assert [c.spec.speed_kmh for c in cases] == [30.0, 50.0, 70.0, 100.0, 100.0]
    assert [c.spec.road for c in cases] == ["iso"] * 4 + ["laplace"]
    for c in cases:
        assert c.spec.noise_fraction == 0.1 and c.spec.duration_s == 120.0 and c.spec.car is FULL
        assert not c.spec.vehicle.tolerances.any and c.spec.truth[0] == 1800.0


def test_every_method_sees_the_same_runs():
    spec = _cases("acceptance")[3].spec
    results = compare(spec, ["rozyn", "likelihood"], [1, 2], jobs=1)
    assert [r.estimate.stage for r in results["likelihood"]] == ["likelihood"] * 2
    for ra, rb in zip(results["rozyn"], results["likelihood"], strict=True):
        a, b = ra.estimate, rb.estimate
        assert a.ok and b.ok and a.n_samples == b.n_samples
        assert b.refinement is not None and b.rozyn is not None
        assert b.rozyn.params is not None and a.params is not None
        assert b.rozyn.params == pytest.approx(a.params)  # the start: Rozyn's on the same samples


def test_the_cli_prints_json_records_per_method(capsys):
    assert main(["compare", "--model", "full", "--seeds", "1-2", "--duration-s", "60", "--noise", "0.1",
                 "--format", "json", "--quiet", "--jobs", "1"]) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["method"] for r in records] == ["rozyn", "likelihood"]
    for r in records:
        assert r["model"] == "full" and r["n"] == 2 and list(r["coverage_95"]) == list(FULL_PARAM_NAMES)


def test_the_text_table_shows_the_lateral_bias_in_millimetres(capsys):
    assert main(["compare", "--model", "full", "--seeds", "1-2", "--duration-s", "60", "--noise", "0.1",
                 "--methods", "likelihood", "--quiet", "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert "full car, iso (gaussian), 100 km/h" in out and "y_c [m]" in out and " mm " in out


@pytest.mark.parametrize(("argv", "message"), [
    (["--bias-mps2", "0.1", "0"], "the full car's accelerometers take no bias"),
    (["--sensor-offsets-m", "0.1", "0"], "--sensor-offsets-m: the half car's sensors"),
    (["--methods", "thesis"], "the full car has likelihood, rozyn"),
    (["--suite", "robustness"], "the full car has the suites acceptance, mismatch"),
    (["--vehicle", "config/vehicle.yaml"], "half-car vehicle file"),
])
def test_what_the_full_car_cannot_compare_is_refused(argv, message, capsys):
    assert main(["compare", "--model", "full", "--seeds", "1", "--quiet", *argv]) == 1
    assert message in capsys.readouterr().err


def _missed_acceptance(preset: str, seeds: range) -> dict[str, object]:
    """Each acceptance case's bars missed on ``seeds`` (empty: all met)."""
    missed = {}
    for case in _cases("acceptance", preset):
        s = summarise(compare(case.spec, ["likelihood"], seeds)["likelihood"])
        assert case.bars is not None
        if bar_failures(s, case.bars, FULL):
            missed[case.label] = bar_failures(s, case.bars, FULL)
    return missed


@pytest.mark.slow
@pytest.mark.parametrize("preset", [
    pytest.param("table5-1", marks=pytest.mark.xfail(strict=True, reason=(
        "seeds 1-100 at 100 km/h: I_xx +0.51 % (standard error 0.23 %; +0.08 +- 0.07 % on 1000 roads) "
        "and the mass's coverage 99 %: what 100 roads can give (docs/uncertainty.md, 1000 roads)"))),
    "second"])
def test_acceptance_100_seeds(preset):
    """The full car's acceptance as stated: every case's bias, 95 % coverage and failures within
    the bars on seeds 1-100."""
    missed = _missed_acceptance(preset, range(1, 101))
    assert not missed, missed


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["table5-1", "second"])
def test_acceptance_1000_seeds(preset):
    """The same bars on 1000 roads, whose standard errors (I_xx's 0.07 % at 100 km/h) resolve
    them: a bias or a std that is off shows here, not the roads' scatter (7 minutes a car)."""
    missed = _missed_acceptance(preset, range(1, 1001))
    assert not missed, missed


def test_the_mismatch_suite_departs_as_it_says():
    cases = _cases("mismatch")
    assert len(cases) == 9 and all(c.bars is not None and c.bars.coverage[0] == 0.90 for c in cases)
    gains = cases[1].spec
    assert gains.departures.corner_gains == (1.03, 0.98, 1.0, 1.02)
    assert gains.estimator_vehicle is gains.vehicle
    tyres = cases[3].spec
    assert tyres.estimator_vehicle.tyre_stiffness_npm[0] == pytest.approx(1e5 / 0.9)
    assert tyres.vehicle.tyre_stiffness_npm[0] == 1e5
    tolerances = tyres.vehicle.tolerances
    assert not tolerances.sensor_gain_front and tolerances.tyre_stiffness_rear_npm == 0.1


def test_a_departure_moves_the_estimate_and_the_uncertainty_covers_it():
    """Four seeds of the suite's gain case: each estimate within 2.5 published std of the truth."""
    case = _cases("mismatch")[1]
    results = compare(case.spec, ["likelihood"], range(1, 5), jobs=1)["likelihood"]
    for est in (r.estimate for r in results):
        assert est.ok
        assert np.all(np.abs(est.params - case.spec.truth) <= 2.5 * est.std)


_SPRINGS = 4  # the mismatch suite's springs case: l_f's std 0.92 of its spread (docs/uncertainty.md)


@pytest.mark.slow
@pytest.mark.parametrize("case", [
    pytest.param(i, marks=pytest.mark.xfail(strict=True, reason="l_f with the springs calibrated: "
                                            "coverage 89 % on seeds 1-100 (std 0.92 of the spread)"))
    if i == _SPRINGS else i for i in range(9)])
def test_mismatch_100_seeds_covers_the_truth(case):
    """The full car departing from its model: the case's 95 % coverage at least 90 % for each
    parameter, no failure (the published std honest; ``rozyn compare --model full --suite
    mismatch`` prints the width bars too)."""
    spec = _cases("mismatch")[case].spec
    s = summarise(compare(spec, ["likelihood"], range(1, 101))["likelihood"])
    assert s.failures == 0 and np.all(s.coverage_95 >= 0.90), s.coverage_95.tolist()
