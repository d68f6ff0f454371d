"""The control loop on simulated time that moves only when driven: lockstep.

``SteppedClock`` is a `TickClock` whose ticks wait until someone grants them: a test (or
a tool) calls :meth:`SteppedClock.advance` with simulated seconds, the loop runs exactly
that many ticks, each starting on its deadline with no lateness, and before each tick the
backend's physics steps by the tick's simulated time (``on_tick(dt_s)``: the MuJoCo twin's
``advance``; the emulator reads the same clock). A run of 10 simulated seconds then takes
the CPU time it needs, and the loop's figures are the same on a loaded machine as on a
quiet one.

Commands need no driver: `Controller.submit` calls :meth:`wake`, which grants one tick,
the one that runs the command and answers it. :meth:`release` (the controller's halt)
lets the loop run freely so it can stop.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from app.control.timing import TickClock


class SteppedClock(TickClock):
    """Lockstep simulated time [s] at ``rate_hz``; ``on_tick(dt_s)`` steps the physics to
    each tick's start (called in the control thread, before the tick's work)."""

    def __init__(self, rate_hz: float, on_tick: Callable[[float], None] | None = None) -> None:
        self._virtual = 0.0
        self._cond = threading.Condition()
        self._granted = 0  # ticks allowed and not yet started
        self._done = 0  # ticks whose work ended
        self._free = False
        self.driven_at = -float("inf")  # time.monotonic() of the last advance
        self.on_tick = on_tick
        super().__init__(rate_hz, spin_s=0.0)

    def now(self) -> float:
        """Simulated time [s] (the loop's clock: pass this as the controller's ``clock``)."""
        return self._virtual

    @property
    def ticks(self) -> int:
        """Ticks run so far."""
        with self._cond:
            return self._done

    def sleep_until(self, deadline: float) -> None:
        with self._cond:
            while self._granted <= 0 and not self._free:
                self._cond.wait()
            self._granted = max(self._granted - 1, 0)
        dt = deadline - self._virtual
        if dt > 0 and self.on_tick is not None:
            self.on_tick(dt)
        self._virtual = max(self._virtual, deadline)

    def end_tick(self) -> None:
        super().end_tick()
        with self._cond:
            self._done += 1
            self._cond.notify_all()

    def wake(self) -> None:
        """A tick for a command just queued (it runs and is answered in that tick), unless
        one is granted already (it will run the command too)."""
        with self._cond:
            if self._granted == 0:
                self._granted = 1
                self._cond.notify_all()

    def release(self) -> None:
        """Run freely from now on (the loop is stopping)."""
        with self._cond:
            self._free = True
            self._cond.notify_all()

    def advance(self, seconds: float, timeout_s: float = 120.0) -> None:
        """Run the loop ``seconds`` [s] of simulated time (rounded to whole ticks, at least
        one) and return once those ticks have ended. Raises ValueError for seconds < 0 and
        TimeoutError when the loop has not run them within ``timeout_s`` of wall time (a
        stopped or stuck loop)."""
        if seconds < 0:
            raise ValueError(f"seconds = {seconds}: must be >= 0")
        n = max(round(seconds / self.period_s), 1)
        self.driven_at = time.monotonic()
        deadline = self.driven_at + timeout_s
        with self._cond:
            target = self._done + n
            self._granted += n
            self._cond.notify_all()
            while self._done < target:
                left = deadline - time.monotonic()
                if left <= 0 or not self._cond.wait(timeout=left):
                    if self._done >= target:
                        break
                    raise TimeoutError(
                        f"the loop ran {n - (target - self._done)} of {n} ticks in "
                        f"{timeout_s:g} s of wall time (is it running?)"
                    )
        self.driven_at = time.monotonic()

    def tick_if_idle(self, idle_s: float) -> bool:
        """Grant one tick when nobody has driven the clock for ``idle_s`` [s] of wall time
        and none is granted (a pacer calls this: a test blocked in a request that waits on
        the loop, or reading telemetry, still sees time pass). True when it granted one."""
        with self._cond:
            if self._granted or time.monotonic() - self.driven_at < idle_s:
                return False
            self._granted = 1
            self._cond.notify_all()
            return True
