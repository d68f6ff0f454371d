"""Waiting in end-to-end tests: on a condition, bounded by a deadline, failing with what it
waited for (and what it last saw); and reading a response body only after its status.

A loaded 2-core machine can make anything slow, so no test sleeps a fixed time and hopes:
it polls for the effect it needs, and the deadline is generous because it is a bound, not
a timing assertion.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

WAIT_S = 30.0  # generous bound for convergence on a loaded 2-core machine; not a timing test


def wait_for(
    condition: Callable[[], Any],
    what: str,
    timeout_s: float = WAIT_S,
    *,
    poll_s: float = 0.02,
    seen: Callable[[], Any] | None = None,
) -> Any:
    """Poll ``condition`` until it returns something truthy, and return that.

    Fails after ``timeout_s`` naming ``what`` it waited for and, when ``seen`` is given,
    what ``seen()`` returned last (e.g. the measured position), so a timeout says how far
    from done it was. With a simulated-time client open (tests/support/sim_time.py) the
    loop's clock is advanced SIM_STEP_S between looks instead, and the wait fails once
    ``timeout_s`` has passed both in simulated and in wall time (a condition may also
    wait on work outside the loop: a worker process, a file).
    """
    from tests.support.sim_time import driven

    clock = driven()
    if clock is not None:
        return _wait_driven(clock, condition, what, timeout_s, seen)
    start = time.monotonic()
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() - start > timeout_s:
            last = f"; last seen: {seen()!r}" if seen is not None else ""
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}{last}")
        time.sleep(poll_s)


SIM_STEP_S = 0.02  # simulated time between two looks at a condition: 4 ticks at 200 Hz
SIM_PAUSE_S = 0.002  # wall time between two looks: simulated time runs at most ~10x real
# a wait still open after this much simulated time most likely waits on wall-time work (a
# worker's check, a report) or a long run: it then looks every SIM_SLOW_PAUSE_S, at most
# ~2x real time, so a spinning loop does not starve that work on a loaded machine
SIM_FAST_S = 2.0
SIM_SLOW_PAUSE_S = 0.01


def _wait_driven(clock, condition, what, timeout_s, seen) -> Any:
    start, wall = clock.now(), time.monotonic()
    while True:
        value = condition()
        if value:
            return value
        if clock.now() - start > timeout_s and time.monotonic() - wall > timeout_s:
            last = f"; last seen: {seen()!r}" if seen is not None else ""
            raise AssertionError(
                f"timed out after {timeout_s:g} s (simulated and wall) waiting for {what}{last}"
            )
        clock.advance(SIM_STEP_S)
        # let the app's other threads run: a condition may wait on their work (a report
        # drawn, a worker's check), which a loop spinning at full speed would slow
        time.sleep(SIM_PAUSE_S if clock.now() - start < SIM_FAST_S else SIM_SLOW_PAUSE_S)


def ok_json(response: Any, status: int = 200) -> Any:
    """The JSON body of ``response`` after checking its status code (an httpx response).

    A refused request then fails as "POST /api/... -> 409: {detail}" instead of a bare
    KeyError on the field the test wanted.
    """
    request = response.request
    assert response.status_code == status, (
        f"{request.method} {request.url.path} -> {response.status_code} (wanted {status}): "
        f"{response.text}"
    )
    return response.json()
