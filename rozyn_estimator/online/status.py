"""What the online estimator's diagnostics say: the level and message, and the key/values (ROS-free).

Pure functions over the estimator's state (:class:`~rozyn_estimator.online.estimator.OnlineEstimator`
calls them under its lock): the most urgent news first, so a failed update, a silent
sensor or a sensor sending only invalid samples is said until it is over.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence

from rozyn_estimator.online.channel import Channel
from rozyn_estimator.online.records import NS, OK, WARN, Layout, Level, Update, update_values


def status(names: Sequence[str], channels: Sequence[Channel], silence_s: float,
           silent_s: Sequence[float] | None, events: Sequence[tuple[Level, str]],
           last: Update | None, lost: int) -> tuple[Level, str]:
    """Level and message, most urgent first: a silent sensor, events, the last update, losses.

    Args:
        names: what to call each sensor (front and rear, or the corners).
        channels: their samples.
        silence_s: a sensor silent (or behind) this long is waited for.
        silent_s: seconds since each sensor's last message arrived (the node's clock), or
            None (a replay: a sensor whose stamps lag the other's is waited for).
        events: events not yet reported (window resets).
        last: the last update (a failed one stands until the next).
        lost: samples dropped or missing since the last report.

    Returns:
        The level and the message.
    """
    waiting = _waiting(names, channels, silence_s, silent_s)
    news = [text for _, text in events]  # resets since the last report: always said
    if waiting:
        waiting.sort(reverse=True)
        return WARN, "; ".join(["waiting for " + "; ".join(text for _, text in waiting), *news])
    if news:
        return max(lv for lv, _ in events), "; ".join(news)
    if last is not None and last.level != OK:
        return last.level, last.message
    if lost > 0:
        return WARN, f"lost {lost} samples since the last report (see dropped/missing)"
    return OK, last.message if last is not None else "collecting the first window"


def _waiting(names: Sequence[str], channels: Sequence[Channel], silence_s: float,
             silent_s: Sequence[float] | None) -> list[tuple[float, str]]:
    """(how long, why) for each sensor waited for: silent, behind the other, or without a valid sample."""
    if silent_s is not None:
        silent = [(s, f"{n}: no message for {s:.1f} s") for n, s in zip(names, silent_s, strict=True)
                  if s > silence_s]
        if silent:
            return silent
    lasts = [ch.last_ns for ch in channels]
    known = [t for t in lasts if t is not None]
    if len(known) == len(channels):
        newest = max(known)
        return [((newest - t) / NS, f"{n}: {(newest - t) / NS:.1f} s behind")
                for n, t in zip(names, known, strict=True) if newest - t > silence_s * NS]
    return [(math.inf, _nothing_yet(n, ch))
            for n, ch in zip(names, channels, strict=True) if ch.last_ns is None]


def _nothing_yet(name: str, ch: Channel) -> str:
    """Why a channel has no sample: nothing arrived, or only invalid samples."""
    if not ch.invalid_run:
        return f"{name}: no message yet"
    if not ch.count:
        return f"{name}: all {ch.invalid_run} samples invalid ({ch.invalid_reason})"
    return f"{name}: {ch.invalid_run} samples invalid since the last valid one ({ch.invalid_reason})"


def health_values(channels: Sequence[Channel], layout: Layout, resets: int, dropped: Counter[str],
                  last: Update | None) -> dict[str, str]:
    """The diagnostics' key/values: counts (``samples_front`` …, per channel of ``layout``),
    drops per reason, and the last update's."""
    values = {"window_fill_pct": f"{(last.window_fill if last else 0.0) * 100:.0f}"}
    values |= {f"samples_{c}": str(ch.count) for c, ch in zip(layout.channels, channels, strict=True)}
    # gaps in the stamps: lost on the way
    values |= {f"missing_{c}": str(ch.missing) for c, ch in zip(layout.channels, channels, strict=True)}
    values |= {"window_resets": str(resets), "dropped_total": str(sum(dropped.values()))}
    for reason, n in sorted(dropped.items()):
        values[f"dropped ({reason})"] = str(n)
    if last is not None:
        values.update(update_values(last, layout))
    return values
