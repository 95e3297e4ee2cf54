"""One description per parameter, one lazy validation helper (rozyn_estimator.parameters)."""

from __future__ import annotations

import array
from dataclasses import dataclass
from typing import ClassVar

import pytest

from rozyn_estimator.errors import ConfigError
from rozyn_estimator.method import PipelineConfig
from rozyn_estimator.online import OnlineConfig
from rozyn_estimator.parameters import Param, build, check, coerce, flatten, param, range_rule


@dataclass(frozen=True)
class Inner:
    PARAM_PREFIX: ClassVar[str] = "outer.inner."

    band_hz: tuple[float, float] = param((1.0, 2.0), "a band", unit="Hz", low=0.0, open_low=True, length=2)
    mode: str = param("a", "a choice", choices=("a", "b"))
    hidden: float = param(1.0, "not a ROS parameter", ros_name="")

    def __post_init__(self) -> None:
        check(self, (("band_hz", lambda c: c.band_hz[0] < c.band_hz[1], "needs min < max"),))


@dataclass(frozen=True)
class Outer:
    PARAM_PREFIX: ClassVar[str] = ""

    window_s: float = param(10.0, "a window", unit="s", low=1.0, high=100.0)
    count: int = param(3, "a count", low=1)
    flag: bool = param(True, "a flag")
    name: str = param("x", "a name", ros_name="label")
    inner: Inner = param(description="nested", default_factory=Inner)

    def __post_init__(self) -> None:
        check(self)


def test_numbers_are_coerced_and_checked():
    assert Outer(window_s=5).window_s == 5.0 and isinstance(Outer(window_s=5).window_s, float)
    with pytest.raises(ConfigError, match=r"^window_s: must lie in \[1, 100\] s, got 500$"):
        Outer(window_s=500)
    with pytest.raises(ConfigError, match=r"window_s: expected a number in s, got True"):
        Outer(window_s=True)
    with pytest.raises(ConfigError, match=r"window_s: expected a number in s, got 'abc'"):
        Outer(window_s="abc")
    with pytest.raises(ConfigError, match=r"window_s: must be finite"):
        Outer(window_s=float("nan"))
    with pytest.raises(ConfigError, match=r"window_s: too large"):
        Outer(window_s=10**400)
    with pytest.raises(ConfigError, match=r"count: expected an integer, got 2.5"):
        Outer(count=2.5)
    with pytest.raises(ConfigError, match=r"count: must be >= 1, got 0"):
        Outer(count=0)
    with pytest.raises(ConfigError, match=r"flag: expected true or false, got 1"):
        Outer(flag=1)


def test_lists_choices_and_names():
    assert Inner(band_hz=[0.5, 4]).band_hz == (0.5, 4.0)
    assert Inner(band_hz=array.array("d", [0.5, 4.0])).band_hz == (0.5, 4.0)  # as rclpy hands them out
    with pytest.raises(ConfigError, match=r"outer.inner.band_hz: expected 2 numbers, got \[1.0\]"):
        Inner(band_hz=[1.0])
    with pytest.raises(ConfigError, match=r"outer.inner.band_hz: expected a list of numbers"):
        Inner(band_hz="1,2")
    with pytest.raises(ConfigError, match=r"outer.inner.band_hz: must be > 0 Hz, got -1"):
        Inner(band_hz=(-1.0, 2.0))
    with pytest.raises(ConfigError, match=r"outer.inner.band_hz: needs min < max, got \(2.0, 1.0\)"):
        Inner(band_hz=(2.0, 1.0))
    with pytest.raises(ConfigError, match=r"outer.inner.mode: must be one of a, b, got 'c'"):
        Inner(mode="c")
    with pytest.raises(ConfigError, match=r"^label: expected a string"):
        Outer(name=3)


def test_rules_are_lazy_and_never_crash():
    """A rule that would raise on a malformed value (IndexError, TypeError) fails as a rule."""
    @dataclass(frozen=True)
    class Loose:
        values: tuple[float, ...] = param((1.0, 2.0), "any number of values")

        def __post_init__(self) -> None:
            check(self, (("values", lambda c: c.values[0] < c.values[1], "needs min < max"),))

    with pytest.raises(ConfigError, match=r"values: needs min < max, got \(1.0,\)"):
        Loose(values=[1.0])


def test_a_huge_value_gives_a_short_message():
    with pytest.raises(ConfigError) as info:
        Outer(window_s="y" * 1_000_000)
    assert len(str(info.value)) < 300


def test_flatten_and_build_round_trip_by_ros_name():
    flat = {f.name: f.value for f in flatten(Outer())}
    assert flat == {"window_s": 10.0, "count": 3, "flag": True, "label": "x",
                    "outer.inner.band_hz": [1.0, 2.0], "outer.inner.mode": "a"}  # hidden: not a ROS name
    built = build(Outer(), {"window_s": 20, "outer.inner.band_hz": [3, 4], "unrelated": 1})
    assert built == Outer(window_s=20.0, inner=Inner(band_hz=(3.0, 4.0)))
    with pytest.raises(ConfigError, match=r"outer.inner.mode"):
        build(Outer(), {"outer.inner.mode": "z"})


def test_range_texts():
    assert range_rule(Param("", unit="s", low=0.0, open_low=True)) == "must be > 0 s"
    assert Param("", low=0.05, high=1.0).range_text() == "[0.05, 1]"
    assert Param("", low=0.0, open_low=True, high=1.0).range_text() == "(0, 1]"
    assert Param("", low=0, high=2**31 - 1).range_text() == "[0, 2147483647]"
    assert Param("", choices=("a", "b")).range_text() == "a \\| b"


def test_coerce_rejects_a_mapping_for_a_list():
    with pytest.raises(ConfigError, match=r"expected a list"):
        coerce("x", Param(""), (1.0,), {"a": 1})


@pytest.mark.parametrize(("config", "changes", "words"), [
    (OnlineConfig, {"update_period_s": 200.0, "window_s": 100.0}, "update_period_s: must be <= window_s"),
    (OnlineConfig, {"window_s": 5000}, r"window_s: must lie in \[1, 3600\] s, got 5000"),
    (PipelineConfig, {"freq_band_hz": (1.0,)}, "pipeline.freq_band_hz: expected 2 numbers"),
    (PipelineConfig, {"refine": "likelihood", "correlation": "free-decay"}, "pipeline.refine: the likelihood"
     " refinement models a road-driven response"),
])
def test_the_configs_use_it(config, changes, words):
    with pytest.raises(ConfigError, match=words):
        config(**changes)
