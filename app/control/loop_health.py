"""The loop-health light: green, amber or red from the loop's last 10 s of timing.

One set of limits for the live light and for a finished run's verdict
(app/runs/health.py): ``THRESHOLDS`` lives here, below both. The light is

- **red** when a run over these 10 s would be judged not healthy: more than 1 % of the
  ticks overran (``max_overrun_share``), a gap between two ticks' starts over 20 ms
  (``max_gap_ms``, four periods at 200 Hz), or the rate under 95 % of its target
  (``min_rate_share``);
- **amber** halfway there: over 0.5 % overruns, a gap over 10 ms, or the rate under 97.5 %;
- **green** otherwise; **unknown** before the loop has two ticks in its window.

The feedback-staleness limits of a run (``max_stale_*``) are not part of the light: the
loop's timing is (a stale reading is the bus's or the simulator's, shown as a fault).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from app.control.timing import WINDOW_S, TimingStats

AMBER_FRACTION = 0.5  # amber at this fraction of the way from perfect to each red limit


@dataclass(frozen=True)
class Thresholds:
    """Where a run (and the light) stops being healthy (app/runs/health.py's docstring)."""

    max_overrun_share: float = 0.01
    max_gap_ms: float = 20.0
    min_rate_share: float = 0.95
    max_stale_ms: float = 20.0
    max_stale_share: float = 0.01


THRESHOLDS = Thresholds()


@dataclass(frozen=True)
class LoopHealth:
    """The light and the figures it was judged on (the last ``window_s`` seconds).

    level: "green" | "amber" | "red" | "unknown"; reasons: one line per limit of that level
    passed (the red limits when red, the amber ones when amber), empty otherwise;
    rate_hz, target_hz [Hz]; rate_share = rate / target; p99_ms: 99th percentile of tick
    lateness [ms]; overruns, ticks: counts in the window; overrun_share = overruns / ticks;
    longest_gap_ms: the longest time between two ticks' starts [ms].
    """

    level: str
    reasons: tuple[str, ...]
    window_s: float
    rate_hz: float
    target_hz: float
    rate_share: float
    p99_ms: float
    overruns: int
    ticks: int
    overrun_share: float
    longest_gap_ms: float


def _limits(thresholds: Thresholds, fraction: float) -> tuple[float, float, float]:
    """(overrun share, gap [ms], rate share) at ``fraction`` of the way to the red limits;
    the gap starts from nothing (0 ms), the rate share from 1."""
    return (
        thresholds.max_overrun_share * fraction,
        thresholds.max_gap_ms * fraction,
        1.0 - (1.0 - thresholds.min_rate_share) * fraction,
    )


def _passed(health: LoopHealth, limits: tuple[float, float, float]) -> list[str]:
    share, gap, rate = limits
    reasons = []
    if health.overrun_share > share:
        reasons.append(
            f"{health.overruns} of {health.ticks} ticks overran ({health.overrun_share:.1%}, "
            f"limit {share:.1%})"
        )
    if health.longest_gap_ms > gap:
        reasons.append(f"a {health.longest_gap_ms:.0f} ms pause between ticks (limit {gap:.0f} ms)")
    if health.rate_share < rate:
        reasons.append(
            f"{health.rate_hz:.0f} Hz of {health.target_hz:.0f} Hz ({health.rate_share:.1%}, "
            f"limit {rate:.1%})"
        )
    return reasons


def classify(window: TimingStats, thresholds: Thresholds = THRESHOLDS) -> LoopHealth:
    """The light for one window of loop timing (TimingRecorder.last_window()).

    Uses window.measured_hz, target_hz, jitter_p99_ms, overruns, ticks, longest_gap_ms.
    Red when a red limit (``thresholds``, see the module docstring) is passed, amber when
    only a limit at AMBER_FRACTION of the way is, green otherwise; "unknown" with fewer than
    two ticks. Never raises for finite figures.
    """
    ticks = int(window.ticks)
    share = window.overruns / ticks if ticks else 0.0
    rate_share = window.measured_hz / window.target_hz if window.target_hz > 0 else 0.0
    health = LoopHealth(
        "unknown",
        (),
        WINDOW_S,
        float(window.measured_hz),
        float(window.target_hz),
        float(rate_share),
        float(window.jitter_p99_ms),
        int(window.overruns),
        ticks,
        float(share),
        float(window.longest_gap_ms),
    )
    if ticks < 2 or window.measured_hz <= 0:
        return health
    red = _passed(health, _limits(thresholds, 1.0))
    if red:
        return replace(health, level="red", reasons=tuple(red))
    amber = _passed(health, _limits(thresholds, AMBER_FRACTION))
    return replace(health, level="amber" if amber else "green", reasons=tuple(amber))
