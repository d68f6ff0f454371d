"""A run's loop health: was the loop and its feedback good enough for the figures to mean
anything?

Read from the run's ticks as logged (app/runs/logs.py COLUMNS), one row per tick:
``gap_ms`` (time since the previous tick started), ``lateness_ms`` (how far the tick
started after its deadline), ``overrun`` (the tick missed its deadline: the previous one
ran into its slot, or slots were skipped; app/control/timing.py ``TickTiming``), ``stale``
(the read brought no news: a simulator whose time did not advance, or a reading unchanged
while the command moved; app/control/safety.py ``FeedbackFreshness``) and ``sim_time_s``.

The run is healthy unless one of these holds (``THRESHOLDS``, also saved in the verdict):

- more than 1 % of its ticks overran (``max_overrun_share``);
- a gap between two ticks over 20 ms, four loop periods at 200 Hz (``max_gap_ms``): the
  robot went unwatched and uncommanded that long;
- the loop rate below 95 % of its target (``min_rate_share``): time ran out of slots;
- feedback stale for over 20 ms in a row (``max_stale_ms``): the loop acted on a reading
  that old; or more than 1 % of the ticks stale (``max_stale_share``): a simulator that
  keeps up only now and then.

On a loaded 2-core machine the thesis sinusoid ran at 141 Hz with pauses up to 318 ms and
a simulator state frozen for 84 ticks, and said ``done`` with RMSE four times the quiet
machine's: each of these rules flags that run (docs/performance.md, "Loop health").
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import asdict
from typing import Any

import numpy as np

from app.control.loop_health import THRESHOLDS, Thresholds  # the live light's limits too


def _number(value: Any) -> float:
    """A logged number (a float, or the text of one from the CSV; empty/None: NaN)."""
    if value is None or value == "":
        return float("nan")
    return float(value)


def _flag(value: Any) -> bool:
    """A logged flag (a bool, or its text from the CSV: "True"/"False", "1"/"0")."""
    if isinstance(value, str):
        return value.strip().lower() in ("true", "1")
    return bool(value)


def longest_true_run(flags: np.ndarray, durations: np.ndarray) -> float:
    """The largest sum of ``durations`` over a run of consecutive True ``flags`` (both (N,))."""
    best = current = 0.0
    for flag, duration in zip(flags.tolist(), durations.tolist(), strict=True):
        current = current + duration if flag else 0.0
        best = max(best, current)
    return best


def assess_series(
    gap_ms: np.ndarray,
    lateness_ms: np.ndarray,
    overrun: np.ndarray,
    stale: np.ndarray,
    target_hz: float,
    simulated: bool = False,
    thresholds: Thresholds = THRESHOLDS,
) -> dict[str, Any]:
    """The verdict on one run's ticks, all arrays (N,), one entry per tick in order.

    gap_ms: time since the previous tick started [ms] (NaN where unknown: a log older
    than the column); lateness_ms [ms]; overrun, stale: flags; target_hz: the loop's rate
    [Hz]; simulated: the feedback came from a simulator (only changes the reason's words).

    Returns ``{"ok", "reasons", "rate_hz", "lateness_ms": {"p50", "p99", "worst"},
    "overruns", "overrun_share", "longest_gap_ms", "stale_ticks", "longest_stale_ms",
    "thresholds"}``. rate_hz = ticks / summed gaps; a stale stretch lasts the sum of the gaps
    of its stale ticks, i.e. from the last fresh read to the last stale one.
    """
    gaps = np.asarray(gap_ms, dtype=np.float64)
    known = np.isfinite(gaps)
    lateness = np.asarray(lateness_ms, dtype=np.float64)
    lateness = lateness[np.isfinite(lateness)]
    overrun = np.asarray(overrun, dtype=bool)
    stale = np.asarray(stale, dtype=bool)
    ticks = int(len(gaps))
    elapsed_ms = float(gaps[known].sum())
    rate = float(known.sum() / elapsed_ms * 1e3) if elapsed_ms > 0 else 0.0
    p50, p99 = np.percentile(lateness, [50, 99]) if lateness.size else (0.0, 0.0)
    overruns = int(overrun.sum())
    share = overruns / ticks if ticks else 0.0
    longest_gap = float(gaps[known].max()) if known.any() else 0.0
    stale_ticks = int(stale.sum())
    longest_stale = longest_true_run(stale, np.where(known, gaps, 0.0))
    limits = thresholds
    reasons = []
    if share > limits.max_overrun_share:
        reasons.append(
            f"{overruns} of {ticks} ticks overran ({share:.1%}, limit "
            f"{limits.max_overrun_share:.0%})"
        )
    if longest_gap > limits.max_gap_ms:
        reasons.append(
            f"the loop paused {longest_gap:.0f} ms between two ticks (limit "
            f"{limits.max_gap_ms:.0f} ms)"
        )
    if elapsed_ms > 0 and rate < limits.min_rate_share * target_hz:
        reasons.append(
            f"the loop ran at {rate:.0f} Hz of {target_hz:.0f} Hz (limit "
            f"{limits.min_rate_share:.0%})"
        )
    what = "the simulator's time did not advance" if simulated else "the reading did not change"
    if longest_stale > limits.max_stale_ms:
        reasons.append(
            f"stale feedback: {what} for {longest_stale:.0f} ms (limit "
            f"{limits.max_stale_ms:.0f} ms)"
        )
    if ticks and stale_ticks / ticks > limits.max_stale_share:
        reasons.append(
            f"stale feedback on {stale_ticks} of {ticks} ticks ({stale_ticks / ticks:.1%}, "
            f"limit {limits.max_stale_share:.0%}): {what}"
        )
    return {
        "ok": not reasons,
        "reasons": reasons,
        "rate_hz": rate,
        "lateness_ms": {
            "p50": float(p50),
            "p99": float(p99),
            "worst": float(lateness.max()) if lateness.size else 0.0,
        },
        "overruns": overruns,
        "overrun_share": share,
        "longest_gap_ms": longest_gap,
        "stale_ticks": stale_ticks,
        "longest_stale_ms": longest_stale,
        "thresholds": asdict(limits),
    }


def assess(
    rows: Iterable[Mapping[str, Any]], target_hz: float, thresholds: Thresholds = THRESHOLDS
) -> dict[str, Any]:
    """The verdict (see :func:`assess_series`) on a run's logged rows: the recorder's rows,
    the MCAP messages (``read_messages``) or the CSV's rows as text. A row without the
    health columns (a log older than them) counts as an on-time, fresh tick of unknown gap.
    """
    rows = list(rows)
    sim = np.array([_number(r.get("sim_time_s")) for r in rows])
    return assess_series(
        np.array([_number(r.get("gap_ms")) for r in rows]),
        np.array([_number(r.get("lateness_ms")) for r in rows]),
        np.array([_flag(r.get("overrun")) for r in rows], dtype=bool),
        np.array([_flag(r.get("stale")) for r in rows], dtype=bool),
        target_hz,
        simulated=bool(np.isfinite(sim).any()),
        thresholds=thresholds,
    )


def summary(health: Mapping[str, Any] | None) -> str:
    """One line for people: "loop health: OK" or "loop health: NOT OK — reasons"."""
    if not health:
        return "loop health: unknown (no ticks recorded)"
    if health.get("ok"):
        return "loop health: OK"
    return "loop health: NOT OK — " + "; ".join(health.get("reasons", []))
