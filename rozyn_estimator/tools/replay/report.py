"""The closing report of ``rozyn replay``: throughput, configuration, the estimates, checks.

The table shows the last updates (the CSV holds them all); then the mean over the
published estimates, the comparison with the sim's ground truth when the bag has
``/sim/ground_truth``, and with the estimates the node published in the recording
(``/inertia``) at the same stamps.
"""

from __future__ import annotations

import numpy as np

from rozyn_estimator.bag import absolute_topic
from rozyn_estimator.method.information import describe
from rozyn_estimator.online import LEVEL_NAMES, NS
from rozyn_estimator.tools.replay.outputs import (
    PUBLISHED_TOPIC,
    TRUTH_TOPIC,
    ReplayResult,
    published_estimate,
)


def format_summary(result: ReplayResult) -> str:
    """The closing report: throughput, configuration, a table of the estimates, checks.

    Args:
        result: what the replay did.

    Returns:
        The report, lines joined by newlines.
    """
    cfg = result.config
    block = cfg.model_vehicle.sensors
    sources = f"{block.describe()}" if block is not None else \
        f"{', '.join(absolute_topic(t) for _, t in cfg.sensors)}, {cfg.field}"
    lines = [
        f"replayed {result.bag} ({cfg.model} car): {result.accel_messages} "
        f"{'sensor' if block is not None else 'accelerometer'} messages ({sources})"
        + (
            f" and {result.speed_messages} speed messages ({absolute_topic(cfg.speed_topic)})"
            if cfg.speed_topic
            else ""
        ),
        f"  read, decoded and fed in {result.feed_s:.2f} s ({result.messages_per_s:,.0f} msg/s); "
        f"{len(result.updates)} updates in {result.update_s:.2f} s",
        f"  configuration: {result.config_source}",
        f"  window {cfg.online.window_s:g} s, update every {cfg.online.update_period_s:g} s, "
        f"pipeline refine={cfg.pipeline.refine}",
    ]
    for note in result.damage:
        lines.append(f"  salvaged: {note}")
    if result.resets or result.dropped:
        dropped = ", ".join(f"{k}: {v}" for k, v in sorted(result.dropped.items())) or "none"
        lines.append(f"  window resets: {result.resets}; dropped: {dropped}")
    lines += ["", _table(result)]
    published = _published_params(result)
    if published:
        p = np.array([params for _, params in published])
        lines.append(f"{'mean over updates':<22}" + "".join(f"{x:>24.6g}" for x in p.mean(axis=0)))
        if result.truth is not None and len(result.truth) == p.shape[1]:
            lines.append(
                f"{'truth (' + TRUTH_TOPIC + ')':<22}" + "".join(f"{x:>24.6g}" for x in result.truth)
            )
            lines.append(f"{'last vs truth':<22}" + "".join(_error(x, t, name) for x, t, name in zip(
                p[-1], result.truth, _columns(p.shape[1]), strict=True)))
    lines += _channel_shares(result)
    if result.recorded:
        lines.append(_against_recorded(result))
    if result.out_dir is not None:
        counts = ", ".join(f"{t} {n}" for t, n in result.out_counts.items())
        lines += [
            "",
            f"wrote {result.out_dir / 'updates.csv'}"
            + (f" and {result.out_dir / 'estimates'} ({counts})" if counts else ""),
        ]
    if result.plot is not None:
        lines.append(f"plot: {result.plot}")
    return "\n".join(lines)


def _channel_shares(result: ReplayResult) -> list[str]:
    """What each channel carries in the last published refined estimate: the share of each
    parameter's information lost without it (:mod:`rozyn_estimator.method.information`)."""
    for ru in reversed(result.updates):
        est = published_estimate(ru.update)
        lost = est.refinement.information_lost if est is not None and est.refinement is not None else ()
        if est is not None and lost:
            layout = result.config.layout
            width = max(len(c) for c in layout.channels)
            return ["", "information lost without each channel (the last estimate):"] + [
                f"  {c:<{width}}  {describe(row, layout.params)}" for c, row in zip(layout.channels, lost,
                                                                                  strict=False)]
    return []


def _published_params(result: ReplayResult) -> list[tuple[int, np.ndarray]]:
    """(stamp [ns], the published (m, I, lf)) of the updates that published, in order."""
    out = []
    for ru in result.updates:
        est = published_estimate(ru.update)
        if est is not None and est.params is not None:
            out.append((ru.update.stamp_ns, est.params))
    return out


HALF_COLUMNS = ("mass [kg]", "pitch inertia [kg m2]", "CoG from front [m]")
FULL_COLUMNS = ("mass [kg]", "roll inertia [kg m2]", "pitch inertia [kg m2]", "CoG from front [m]",
                "CoG left [m]")


def _columns(k: int) -> tuple[str, ...]:
    return FULL_COLUMNS if k == len(FULL_COLUMNS) else HALF_COLUMNS


def _error(value: float, truth: float, column: str) -> str:
    """The last estimate against the truth: in % of it, the lateral CoG (often 0) in m."""
    if column == FULL_COLUMNS[-1]:
        return f"{f'{value - truth:+.4f} m':>24}"
    return f"{(value / truth - 1) * 100:>+23.2f}%"


def _table(result: ReplayResult, max_rows: int = 24) -> str:
    head = f"{'stamp [s]':>12}  {'status':<6}" + "".join(
        f"{c:>24}" for c in _columns(5 if result.config.model == "full" else 3))
    rows = [head]
    updates = result.updates
    shown = updates if len(updates) <= max_rows else updates[-max_rows:]
    if len(shown) < len(updates):
        rows.append(f"{'…':>12}  ({len(updates) - len(shown)} earlier updates in the CSV)")
    for ru in shown:
        u = ru.update
        est = published_estimate(u)
        if est is not None and est.params is not None:
            std = est.std if est.std is not None else np.full(len(est.params), np.nan)
            cells = "".join(f"{f'{v:.6g} ± {s:.3g}':>24}" for v, s in zip(est.params, std, strict=True))
        else:
            cells = f"  {u.message if len(u.message) <= 90 else u.message[:89] + '…'}"
        rows.append(f"{u.stamp_ns / NS:>12.3f}  {LEVEL_NAMES[u.level]:<6}{cells}")
    return "\n".join(rows)


def _against_recorded(result: ReplayResult) -> str:
    """How the replayed estimates compare with those the node published in the bag."""
    replayed = dict(_published_params(result))
    common = sorted(set(replayed) & set(result.recorded))
    if not common:
        return f"no stamp of the {len(result.recorded)} estimates on {PUBLISHED_TOPIC} is in the replay"
    # relative, and absolute where the replay's value is 0 (a lateral CoG on the centreline)
    rel = max(float(np.max(np.abs(np.array(result.recorded[s]) - replayed[s])
                           / np.where(replayed[s] != 0, np.abs(replayed[s]), 1.0))) for s in common)
    text = (
        f"against the {len(result.recorded)} estimates recorded on {PUBLISHED_TOPIC}: {len(common)} at "
        f"the same stamps, max relative difference {rel:.1e}"
    )
    extra, missing = len(set(replayed) - set(result.recorded)), len(set(result.recorded) - set(replayed))
    if extra:
        text += f"; {extra} more in the replay (not yet published when the recording stopped?)"
    if missing:
        text += f"; {missing} recorded ones the replay does not have"
    return text
