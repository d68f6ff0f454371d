"""The loop on simulated time (app/control/sim_time.py) by its laws: it runs exactly the
ticks it is given, each on its deadline; the physics steps exactly the time advanced; a
queued command runs without a driver; and an app on it gives the same figures twice."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from app.control.sim_time import SteppedClock
from tests.support.app_client import make_client, torque_on
from tests.support.lease import take_lease
from tests.support.wait import ok_json


def _loop(clock: SteppedClock, stop: threading.Event, seen: list) -> threading.Thread:
    def run() -> None:
        while not stop.is_set():
            deadline, lateness = clock.wait_next()
            seen.append((deadline, lateness, clock.now()))
            clock.end_tick()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_a_stepped_clock_runs_exactly_the_ticks_advanced_each_on_its_deadline():
    steps: list[float] = []
    clock = SteppedClock(200.0, on_tick=steps.append)
    stop, seen = threading.Event(), []
    thread = _loop(clock, stop, seen)
    clock.advance(0.5)  # 100 ticks
    assert clock.ticks == 100 and len(seen) == 100
    assert clock.now() == pytest.approx(0.5)
    assert sum(steps) == pytest.approx(0.5)  # the physics stepped exactly that much
    assert all(lateness == 0.0 and now == deadline for deadline, lateness, now in seen)
    assert clock.last.overrun is False and clock.last.skipped == 0
    clock.wake()  # a command: one tick more, with no driver
    clock.advance(0.0)  # at least one tick: returns once both have run
    assert clock.ticks in (101, 102)
    stop.set()
    clock.release()
    thread.join(timeout=5)
    assert not thread.is_alive()


def test_advance_refuses_a_negative_time_and_says_when_the_loop_does_not_run():
    clock = SteppedClock(200.0)
    with pytest.raises(ValueError, match="seconds"):
        clock.advance(-1.0)
    with pytest.raises(TimeoutError, match="0 of 2 ticks"):
        clock.advance(0.01, timeout_s=0.05)  # nothing ticks it


def _figures(folder) -> tuple:
    with make_client(folder, backend="sim", sim_time=True) as client:
        take_lease(client)
        torque_on(client)
        goal = [0.03, -0.02, -0.25]
        ok_json(client.post("/api/move", json={"position_m": goal}))
        client.app.state.backend.sim_clock.advance(1.5)
        status = ok_json(client.get("/api/status"))
        loop = status["loop"]
        return tuple(status["ee"]["platform_m"]), loop["overruns"], loop["jitter_p99_ms"]


@pytest.mark.slow  # two apps on the twin
def test_an_app_on_simulated_time_gives_the_same_figures_twice(tmp_path):
    first = _figures(tmp_path / "a")
    second = _figures(tmp_path / "b")
    # no tick late, no jitter: simulated time, however loaded the machine was each time
    assert first[1:] == second[1:] == (0, 0.0)
    # the same place: at rest the servos dither by an encoder tick (~0.2 mm at the tip),
    # and the pacer may add a tick or two between the commands (tests/support/sim_time.py)
    np.testing.assert_allclose(first[0], second[0], atol=5e-4)
    np.testing.assert_allclose(first[0], [0.03, -0.02, -0.25], atol=5e-4)
