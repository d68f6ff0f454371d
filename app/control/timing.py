"""Absolute-deadline tick timing and its statistics.

Tick k is due at t0 + k * period: a late tick never shifts the ones after it (no drift).
Measured on this 2-core machine (docs/performance.md, "Control loop"): asyncio.sleep to
each deadline gave p99 lateness 1.2 ms; a dedicated thread that time.sleep()s to 0.3 ms
before the deadline and busy-waits the rest gave p99 0.02 ms for ~3 % of one core.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

WINDOW_S = 10.0


@dataclass(frozen=True)
class TimingStats:
    """Loop timing figures. Lateness is how far a tick started after its deadline [ms]."""

    target_hz: float
    measured_hz: float
    period_mean_ms: float
    jitter_p50_ms: float
    jitter_p99_ms: float
    worst_ms: float
    overruns: int
    ticks: int
    longest_gap_ms: float = 0.0  # the longest time between two ticks' starts [ms]


@dataclass(frozen=True)
class TickTiming:
    """How one tick started, as the loop saw it then (what a run logs per tick).

    lateness_s: how far the tick started after its deadline [s]; gap_s: time since the
    previous tick started [s] (0 for the first tick); overrun: the tick missed its deadline,
    either because the previous tick ended after it (its work, or its own late start, ran
    into this slot) or because whole slots were skipped; skipped: slots skipped before it.
    Over a run, the ticks with ``overrun`` are the ones TimingRecorder counts as overruns
    (one tick later: the tick that ran long makes the next one miss its deadline).
    """

    lateness_s: float = 0.0
    gap_s: float = 0.0
    overrun: bool = False
    skipped: int = 0


class TickClock:
    """Sleeps to absolute deadlines; skips slots it missed by a whole period and says so.

    Call :meth:`wait_next` at the top of each tick and :meth:`end_tick` after its work;
    :attr:`last` is then the tick's :class:`TickTiming`. :meth:`now` is the clock it uses
    (time.perf_counter); a test may subclass it to run the loop on a virtual clock.
    """

    def __init__(self, rate_hz: float, spin_s: float = 3e-4) -> None:
        self.period_s = 1.0 / rate_hz
        self.spin_s = spin_s
        self._start = self.now()
        self._tick = 0
        self._started: float | None = None  # when the previous tick started
        self._ended = -float("inf")  # when the previous tick's work ended
        self.last = TickTiming()

    def now(self) -> float:
        """The clock's time [s] (time.perf_counter)."""
        return time.perf_counter()

    def sleep_until(self, deadline: float) -> None:
        """Sleep to 0.3 ms before ``deadline`` and busy-wait the rest."""
        remaining = deadline - self.spin_s - self.now()
        if remaining > 0:
            time.sleep(remaining)
        while self.now() < deadline:
            pass  # the last few hundred microseconds: time.sleep overshoots by ~50-150 us

    def wait_next(self) -> tuple[float, float]:
        """Block until the next deadline; return (deadline, lateness) [s, perf_counter]."""
        self._tick += 1
        deadline = self._start + self._tick * self.period_s
        missed_own = self._ended > deadline  # the previous tick ran into this slot
        now = self.now()
        missed = 0
        if now - deadline >= self.period_s:  # hopelessly late: skip missed slots, say so
            missed = int((now - deadline) / self.period_s)
            self._tick += missed
            deadline += missed * self.period_s
        self.sleep_until(deadline)
        started = self.now()
        gap = 0.0 if self._started is None else started - self._started
        self._started = started
        self.last = TickTiming(started - deadline, gap, missed_own or missed > 0, missed)
        return deadline, started - deadline

    def end_tick(self) -> None:
        """The tick's work is done (the next tick checks whether it ran past its deadline)."""
        self._ended = self.now()

    def wake(self) -> None:
        """A command was queued for the next tick (the real clock's ticks come anyway; a
        simulated one that waits to be driven runs a tick for it: app/control/sim_time.py)."""

    def release(self) -> None:
        """The loop is stopping: never hold a tick back again (nothing to do in real time)."""


class TimingRecorder:
    """Lateness and period of every tick, since start and over the last 10 s.

    Written by the control thread only. The 10 s figures are recomputed there every
    0.25 s into an immutable TimingStats, so readers (status, telemetry at 50 Hz per
    client) pay nothing and never iterate a buffer the loop is writing.
    """

    REFRESH_S = 0.25

    def __init__(self, rate_hz: float) -> None:
        self.target_hz = rate_hz
        self._period_s = 1.0 / rate_hz
        size = max(int(WINDOW_S * rate_hz), 2)
        self._ring = np.zeros((4, size))  # lateness, period, work, gap between starts [s]
        self._filled = 0
        self._histogram = np.zeros(2001, dtype=np.int64)  # 10 us bins up to 20 ms
        self.ticks = 0
        self.overruns = 0
        self.worst_s = 0.0
        self.longest_gap_s = 0.0
        self._first: float | None = None
        self._last: float | None = None
        self._last_lateness_s = 0.0
        self._window = TimingStats(rate_hz, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0)
        self._refreshed_at = 0.0

    def record(self, deadline: float, lateness_s: float, work_s: float) -> None:
        """One tick: its deadline, how late it started and how long its work took [s]."""
        self.ticks += 1
        if self._first is None:
            self._first = self._refreshed_at = deadline
        period = 0.0 if self._last is None else deadline - self._last
        gap = 0.0 if self._last is None else period + lateness_s - self._last_lateness_s
        self._last, self._last_lateness_s = deadline, lateness_s
        self.longest_gap_s = max(self.longest_gap_s, gap)
        self._ring[:, (self.ticks - 1) % self._ring.shape[1]] = (lateness_s, period, work_s, gap)
        self._filled = min(self._filled + 1, self._ring.shape[1])
        self._histogram[min(int(lateness_s * 1e5), 2000)] += 1
        self.worst_s = max(self.worst_s, lateness_s)
        if lateness_s + work_s > self._period_s:
            self.overruns += 1
        if deadline - self._refreshed_at >= self.REFRESH_S:
            self.refresh()

    def refresh(self) -> None:
        """Recompute the 10 s figures now (the control thread does it every 0.25 s)."""
        self._refreshed_at = self._last or 0.0
        self._window = self._compute_window()

    def since_start(self) -> TimingStats:
        counts = np.cumsum(self._histogram)
        total = max(int(counts[-1]), 1)

        def percentile(q: float) -> float:
            return float(np.searchsorted(counts, q * total)) * 0.01  # ms, bin resolution

        span = (self._last or 0.0) - (self._first or 0.0)
        rate = (self.ticks - 1) / span if span > 0 else 0.0
        return TimingStats(
            self.target_hz,
            rate,
            1e3 / rate if rate else 0.0,
            percentile(0.5),
            percentile(0.99),
            self.worst_s * 1e3,
            self.overruns,
            self.ticks,
            self.longest_gap_s * 1e3,
        )

    def last_window(self) -> TimingStats:
        """The same figures over the last 10 s (refreshed every 0.25 s)."""
        return self._window

    def _compute_window(self) -> TimingStats:
        if self._filled < 2:
            return TimingStats(self.target_hz, 0.0, 0.0, 0.0, 0.0, 0.0, 0, self.ticks)
        lateness, periods, work, gaps = self._ring[:, : self._filled]
        periods = periods[periods > 0]
        mean_period = float(periods.mean()) if periods.size else 0.0
        p50, p99 = np.percentile(lateness, [50, 99])
        return TimingStats(
            self.target_hz,
            1.0 / mean_period if mean_period else 0.0,
            mean_period * 1e3,
            float(p50) * 1e3,
            float(p99) * 1e3,
            float(lateness.max()) * 1e3,
            int((lateness + work > self._period_s).sum()),
            self._filled,
            float(gaps.max()) * 1e3,
        )
