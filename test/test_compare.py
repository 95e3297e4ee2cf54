"""``rozyn compare``: methods side by side on the same runs; the acceptance suites (slow)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.tools.cars import HALF, SECOND_VEHICLE
from rozyn_estimator.tools.cli import main
from rozyn_estimator.tools.compare.compare import bar_failures, compare
from rozyn_estimator.tools.compare.suites import SUITES, Bars, suite
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.tools.trial.summary import Summary, summarise

QUICK = ["--seeds", "1-2", "--jobs", "1", "--duration-s", "40", "--quiet"]


def test_methods_see_the_same_runs():
    spec = TrialSpec(amplitudes="gaussian", duration_s=40.0, noise_fraction=0.1)
    results = compare(spec, ["rozyn", "likelihood"], [1, 2], jobs=1)
    for rozyn, refined in zip(results["rozyn"], results["likelihood"], strict=True):
        assert rozyn.seed == refined.seed
        # the refined method's Rozyn stage skips the jackknife, so sums its correlations in one
        # block instead of ten: the same estimate to rounding
        np.testing.assert_allclose(rozyn.estimate.params, refined.estimate.rozyn.params, rtol=1e-9)


def test_compare_table(capsys):
    assert main(["compare", "--methods", "rozyn,likelihood", "--noise", "0.1", *QUICK]) == 0
    out = capsys.readouterr().out
    assert "95 % cover" in out and "likelihood" in out and "l_f [m]" in out
    assert out.count("0/2") == 2  # no failures, both methods


def test_compare_json_and_markdown(capsys):
    assert main(["compare", "--methods", "likelihood", "--format", "json", *QUICK]) == 0
    (record,) = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert record["method"] == "likelihood" and record["n"] == 2 and record["failures"] == 0
    assert set(record["coverage_95"]) == {"mass_kg", "pitch_inertia_kgm2", "cog_from_front_axle_m"}
    assert main(["compare", "--methods", "rozyn", "--format", "markdown", *QUICK]) == 0
    assert "| rozyn | m [kg] |" in capsys.readouterr().out


@pytest.mark.parametrize("args", [["--methods", "rozyn,nope"], ["--methods", ","], ["--seeds", "3-1"]])
def test_bad_options_are_one_line(capsys, args):
    assert main(["compare", *args, *QUICK[2:]]) == 1
    err = capsys.readouterr().err
    assert "error" in err and err.count("\n") == 1


def test_suites():
    base = TrialSpec(vehicle=SECOND_VEHICLE)
    for name in SUITES["half"]:
        cases = suite(name, base)
        assert cases and all(c.spec.vehicle.wheelbase_m == 3.2 or "sensors" in c.label for c in cases)
    acceptance = suite("acceptance", base)
    assert len(acceptance) == 7 and all(c.bars is not None for c in acceptance)
    assert all(c.spec.noise_fraction == 0.1 and c.spec.amplitudes == "gaussian" for c in acceptance)
    assert [c.bars.bias_pct for c in acceptance].count(2.0) == 1  # waviness 2.5
    with pytest.raises(ConfigError, match="suite"):
        suite("nope", base)


def test_bar_failures_name_each_missed_bar():
    def summary(bias, std, coverage, failures=0):
        t = np.array([1000.0, 2000.0, 1.2])
        return Summary(100, failures, t, t, np.array(std), np.array(bias), np.ones(3), np.ones(3), 1.0,
                       coverage_95=np.array(coverage))

    bars = Bars(std=(10.0, 25.0, 0.01))
    assert bar_failures(summary([0.1, -0.2, 0.0], [2.0, 5.0, 0.002], [0.95, 0.93, 0.96]), bars, HALF) == []
    bad = summary([1.5, 0.0, 0.0], [2.0, 30.0, 0.002], [0.95, 0.93, 0.99], failures=2)
    missed = bar_failures(bad, bars, HALF)
    assert missed == ["failures 2/100", "bias m +1.50 %", "std I_yy 30", "coverage l_f 0.99"]


# The refinement's acceptance: 100 seeds per case, Table 5-1 and a second, clearly different vehicle,
# on seeds that no setting was explored on (as test_acceptance.py).
SEEDS = range(501, 601)


@pytest.mark.slow
@pytest.mark.parametrize("vehicle", ["table5-1", "second"])
@pytest.mark.parametrize("index", range(7))
def test_acceptance(vehicle, index):
    base = TrialSpec(vehicle=SECOND_VEHICLE) if vehicle == "second" else TrialSpec()
    case = suite("acceptance", base)[index]
    results = compare(case.spec, ["likelihood"], SEEDS, jobs=2)["likelihood"]
    # The bars hold for bias, spread and failures as they are. A coverage from 100
    # seeds is a binomial count: even a calibrated 95 % interval lands outside the issue's
    # 90-98 % in about one parameter-case in six by chance (docs/results.md reports the
    # bars on seeds 1-100). So here: no parameter under-covers (>= 88 %: below that a
    # calibrated interval has under 0.3 % chance), and the three together cover 89-99 % (one
    # seed's three parameters are correlated: their mean spreads nearly as much as one).
    s = summarise(results)
    assert bar_failures(s, dataclasses.replace(case.bars, coverage=(0.88, 1.0)), HALF) == [], case.label
    assert 0.89 <= float(np.mean(s.coverage_95)) <= 0.99, (case.label, s.coverage_95)


# The mismatch suite's cases on held-out seeds (docs/results.md reports
# seeds 1-100). Coverage from 100 seeds is a binomial count: as above, a bar of 88 % per
# parameter (a calibrated interval falls below it with under 0.3 % chance).
MISMATCH = suite("mismatch", TrialSpec())
WARNS = {"dampers 2x": 0.80}  # the model check must warn (a sensor late within its tolerance is
# calibrated and reported, and the model then fits)
IN_MODEL = "the model itself"  # ... and must not


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(MISMATCH)), ids=[c.label[:40] for c in MISMATCH])
def test_mismatch(index):
    case = MISMATCH[index]
    s = summarise(compare(case.spec, ["likelihood"], SEEDS, jobs=2)["likelihood"])
    assert bar_failures(s, dataclasses.replace(case.bars, coverage=(0.88, 1.0)), HALF) == [], case.label
    warns = [share for start, share in WARNS.items() if case.label.startswith(start)]
    if warns:
        assert s.model_warn_share >= warns[0], (case.label, s.model_warn_share)
    if case.label.startswith(IN_MODEL):
        assert s.model_warn_share <= 0.05, (case.label, s.model_warn_share)


def test_the_sensors_suite_sets_one_imu_against_the_accelerometers_on_both_cars():
    from rozyn_estimator.vehicle_full import FullVehicle

    half = suite("sensors", TrialSpec(vehicle=SECOND_VEHICLE))
    assert [c.spec.vehicle.sensors is not None for c in half] == [False, True, True, True, True]
    assert half[1].spec.vehicle.channel_names == ("imu.accel_z", "imu.gyro_y")
    assert half[1].spec.vehicle.tolerances.any is False and half[2].spec.vehicle.tolerances.any
    assert half[3].spec.vehicle.channel_names == ("front.accel_z", "imu.accel_z", "rear.accel_z",
                                                  "imu.gyro_y")
    assert half[4].spec.vehicle.sensor_x_m == (0.0, 1.6, 3.2)  # the second vehicle's wheelbase: 3.2 m
    full = suite("sensors", TrialSpec(vehicle=FullVehicle()))
    kinds = [c.spec.vehicle.channel_kinds for c in full]
    assert kinds[0] == ("accel_z",) * 4 and kinds[1] == ("accel_z", "gyro_x", "gyro_y")
    assert kinds[3] == ("accel_z", "gyro_x", "gyro_y", "accel_z", "accel_z")
    assert kinds[4] == ("accel_z", "gyro_x", "gyro_y", "accel_z") and kinds[5] == ("accel_z",) * 3
    assert full[-1].spec.departures.gyro_yaw_misalignment_rad > 0 and full[-1].bars.coverage[1] == 1.0
    assert all(c.spec.noise_fraction == 0.1 and c.spec.duration_s == 120.0 for c in full)


def test_the_drive_cycles_suite_drives_each_shipped_cycle_on_both_cars():
    from rozyn_estimator.vehicle_full import FullVehicle

    for vehicle in (SECOND_VEHICLE, FullVehicle()):
        cases = suite("drive-cycles", TrialSpec(vehicle=vehicle))
        assert {c.spec.drive_cycle for c in cases} == {"udds", "hwfet", "wltc3b"}
        assert all(c.spec.duration_s == 300.0 and c.bars is not None for c in cases)
        assert any(c.spec.vehicle.cog_height_m > 0 for c in cases)  # the load transfer on
        own = [c for c in cases if c.spec.vehicle.tolerances == vehicle.tolerances]
        assert len(own) == 1 and own[0].bars.bias_pct is None
