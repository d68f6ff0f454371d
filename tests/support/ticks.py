"""A control loop clock for tests: virtual time, no sleeping, stalls on demand.

``VirtualTickClock`` paces a real controller thread (``Controller(..., tick_clock=...,
clock=ticks.now)``) on virtual time: every tick starts exactly on its deadline and its work
takes no time, so a run's loop figures are known in advance, on any machine, however
loaded. ``stalls={tick: seconds}`` makes that tick start so much late, as a starved loop
does.
"""

from __future__ import annotations

import time

from app.control.timing import TickClock


class VirtualTickClock(TickClock):
    """TickClock on virtual time [s]: ticks start on their deadlines; ``stalls`` delays some."""

    def __init__(self, rate_hz: float, stalls: dict[int, float] | None = None) -> None:
        self._virtual = 0.0
        self.stalls = dict(stalls or {})
        self.ticks = 0
        super().__init__(rate_hz, spin_s=0.0)

    def now(self) -> float:
        return self._virtual

    def sleep_until(self, deadline: float) -> None:
        self.ticks += 1
        self._virtual = max(self._virtual, deadline) + self.stalls.pop(self.ticks, 0.0)
        time.sleep(0)  # let the other threads run: this loop never waits
