"""Helpers of the study tests: a Ctrl-C in the middle of a study run."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import pytest

from rozyn_estimator.tools.study import work


@contextlib.contextmanager
def ctrl_c_at_chunk(n: int) -> Iterator[None]:
    """Within the block, ``work.run_chunk`` raises KeyboardInterrupt (as Ctrl-C) at its ``n``-th
    call (run_study looks it up there: local_results runs chunks in this process with --jobs 1)."""
    real_run_chunk = work.run_chunk
    calls = 0

    def interrupted(chunk: work.Chunk) -> list:
        nonlocal calls
        calls += 1
        if calls == n:
            raise KeyboardInterrupt
        return real_run_chunk(chunk)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(work, "run_chunk", interrupted)
        yield
