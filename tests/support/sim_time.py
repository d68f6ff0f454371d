"""Tests on simulated time: the app's loop in lockstep (app/control/sim_time.py).

``make_client(..., sim_time=True)`` opens the backend on a `SteppedClock`; while such a
client is open (its ``with`` block), it is the *driven clock*: `tests.support.wait.wait_for`
advances it between looks at its condition instead of sleeping, and :func:`elapse` runs
the loop a given simulated time (or sleeps that long where no clock is driven). Commands
need nothing: each one queued runs a tick. When the test drives nothing for IDLE_S (it is
blocked in a request that waits on the loop, or reads telemetry), a pacer thread lets the
loop run at about real time, one tick per period, so nothing waits forever; the figures a
test measures come from its driven waits.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from app.control.sim_time import SteppedClock

_driven: list[SteppedClock] = []
IDLE_S = 0.05  # wall time without driving after which the pacer ticks the loop


def driven() -> SteppedClock | None:
    """The clock a test drives now (the innermost open simulated-time client), or None."""
    return _driven[-1] if _driven else None


@contextmanager
def driving(clock: SteppedClock) -> Iterator[SteppedClock]:
    """Make ``clock`` the driven one inside the block, with its pacer (module doc)."""
    stop = threading.Event()

    def pace() -> None:
        while not stop.wait(clock.period_s):
            clock.tick_if_idle(IDLE_S)

    pacer = threading.Thread(target=pace, name="sim-time-pacer", daemon=True)
    clock.driven_at = time.monotonic()
    _driven.append(clock)
    pacer.start()
    try:
        yield clock
    finally:
        stop.set()
        pacer.join(timeout=2.0)
        _driven.remove(clock)


def elapse(seconds: float) -> None:
    """Let ``seconds`` [s] pass for the robot: the driven clock runs that long, else (real
    time) a sleep. What a test does to see that nothing happens in a while."""
    clock = driven()
    if clock is None:
        time.sleep(seconds)
    else:
        clock.advance(seconds)
