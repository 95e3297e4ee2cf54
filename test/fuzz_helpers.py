"""Helpers of the property-based tests (``test_fuzz*.py``): budgets, the runner, shared strategies."""

from __future__ import annotations

import warnings
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

FULL = 10_000
FLOATS = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
    [0.0, -0.0, 1e308, -1e308, 5e-324, 1e-308, 1e300, 9.81, 1e6])


def budgets(quick: int) -> list[Any]:
    """The quick budget in the default suite, FULL examples in the slow one."""
    return [pytest.param(quick, id="quick"), pytest.param(FULL, id="10k", marks=pytest.mark.slow)]


def run(examples: int, strategy: st.SearchStrategy[Any], check: Callable[[Any], None], name: str) -> None:
    """Check the property on ``examples`` examples; numerical warnings recorded, then listed."""
    seen: Counter[str] = Counter()
    count = 0

    @settings(max_examples=examples, deadline=None, database=None, derandomize=examples < FULL,
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def prop(case: Any) -> None:
        nonlocal count
        count += 1
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check(case)
        seen.update(f"{Path(w.filename).name}:{w.lineno} {w.category.__name__}: {w.message}" for w in caught
                    if issubclass(w.category, RuntimeWarning))

    prop()
    print(f"\n{name}: {count} examples, no exception escaped")
    for where, n in seen.most_common():
        print(f"  numerical warning in {n} examples: {where}")
    if examples >= FULL:
        assert count >= FULL


def one_line(text: str) -> None:
    """An error message a user can read: one bounded line."""
    assert text and "\n" not in text and len(text) <= 4500, text
