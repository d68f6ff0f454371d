"""Every run carries its loop's health: a run with an injected stall (the simulator paused,
the loop starved) is flagged with its reason, a healthy one is not.

The controller thread runs on a virtual clock (tests/support/ticks.py) over a fake bus, so
a healthy run's loop is perfect on any machine and a stall is exactly the one put in; one
test starves the real-time loop and one pauses the real simulator, and only assert that
the run is flagged (an injected stall is there however loaded the machine).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from app.config import load_settings
from app.control.controller import Controller
from app.control.state import Snapshot
from app.control.timing import TickClock
from app.runs.logs import COLUMNS
from app.runs.manager import RunManager
from app.runs.run import Run
from app.runs.trajectories import SinusoidParams
from tests.support.fake_bus import FakeBus
from tests.support.ticks import VirtualTickClock
from tests.support.wait import WAIT_S

SHORT = SinusoidParams(duration_s=1.0)
HZ = 200.0


@contextmanager
def loop(bus, folder: Path, ticks: TickClock | None = None, **settings) -> Iterator[Controller]:
    """A started controller over ``bus`` with torque on; ``ticks`` paces it (None: real time)."""
    config = load_settings(runs={"folder": str(folder)}, **settings)
    clock = {} if ticks is None else {"clock": ticks.now, "tick_clock": ticks}
    controller = Controller(config, bus, "fake", **clock)
    controller.start()
    try:
        controller.set_torque(True).result(timeout=WAIT_S)
        yield controller
    finally:
        controller.stop()


def run_with(controller: Controller, folder: Path, on_tick: Callable[[Snapshot], None]) -> Run:
    """A short sinusoid run with ``on_tick`` called in the control thread every tick of it."""
    controller.add_listener(on_tick)
    run = RunManager(controller, folder).start_sinusoid(SHORT)
    assert run.done.wait(4 * WAIT_S), "the run did not end (and its report drawn)"
    controller.remove_listener(on_tick)
    return run


class Once:
    """From the first tick of the run's timed part: ``start()``, then ``stop()`` ``ticks``
    ticks later (in the control thread, so exactly then)."""

    def __init__(self, start: Callable[[], None], stop: Callable[[], None], ticks: int) -> None:
        self.start, self.stop, self.ticks, self.seen = start, stop, ticks, -1

    def __call__(self, snap: Snapshot) -> None:
        if self.seen < 0 and snap.phase != "timed":
            return
        self.seen += 1
        if self.seen == 0:
            self.start()
        elif self.seen == self.ticks:
            self.stop()


@pytest.mark.slow  # a run on the twin
def test_a_healthy_run_is_not_flagged_and_logs_its_tick_figures(tmp_path):
    bus = FakeBus(sim_step_s=0.005)
    with loop(bus, tmp_path, VirtualTickClock(HZ)) as controller:
        run = run_with(controller, tmp_path, lambda snap: None)
    health = run.stats["health"]
    assert run.state == "done" and health["ok"] and health["reasons"] == []
    assert health["rate_hz"] == pytest.approx(HZ) and health["longest_gap_ms"] == pytest.approx(5)
    assert (health["overruns"], health["stale_ticks"], health["longest_stale_ms"]) == (0, 0, 0)
    saved = json.loads((run.folder / "run.json").read_text())
    assert saved["stats"]["health"] == health
    with open(run.folder / "log.csv") as file:
        rows = list(csv.DictReader(file))
    assert list(rows[0]) == COLUMNS and len(rows) == run.samples
    times = [float(r["sim_time_s"]) for r in rows]
    assert all(b > a for a, b in zip(times, times[1:], strict=False))  # each read was news
    assert {r["stale"] for r in rows} == {"False"} and {r["overrun"] for r in rows} == {"False"}


@pytest.mark.slow  # a run on the twin
def test_a_starved_loop_is_flagged_with_its_pause(tmp_path):
    ticks = VirtualTickClock(HZ)
    stall = Once(lambda: ticks.stalls.update({ticks.ticks + 1: 0.1}), lambda: None, 1)
    with loop(FakeBus(sim_step_s=0.005), tmp_path, ticks) as controller:
        run = run_with(controller, tmp_path, stall)
    health = run.stats["health"]
    assert not health["ok"]
    assert health["longest_gap_ms"] == pytest.approx(105.0)  # the stall and its own period
    assert health["lateness_ms"]["worst"] == pytest.approx(100.0)
    assert health["overruns"] == 1  # the tick after the stall found its slot gone
    assert health["reasons"][0] == "the loop paused 105 ms between two ticks (limit 20 ms)"


@pytest.mark.slow  # a run on the twin
def test_a_paused_simulator_is_flagged_as_stale_feedback_not_a_lagging_joint(tmp_path):
    bus = FakeBus(sim_step_s=0.005)
    pause = Once(lambda: setattr(bus, "paused", True), lambda: setattr(bus, "paused", False), 40)
    # a following error this tight trips within 0.05 s on a reading frozen for 0.2 s (the
    # fake servo is one tick behind: up to 0.035 rad in z's 1 m/s)
    tight = {"following_error_rad": 0.06, "following_error_time_s": 0.05}
    with loop(bus, tmp_path, VirtualTickClock(HZ), safety=tight) as controller:
        run = run_with(controller, tmp_path, pause)
    health = run.stats["health"]
    assert run.state == "done", run.reason  # no following error on the frozen reading
    assert not health["ok"] and health["stale_ticks"] == 40
    assert health["longest_stale_ms"] == pytest.approx(200.0)
    assert (
        "stale feedback: the simulator's time did not advance for 200 ms (limit 20 ms)"
        in health["reasons"]
    )


@pytest.mark.slow  # a run on the twin
def test_a_simulator_paused_too_long_faults_naming_stale_feedback(tmp_path):
    bus = FakeBus(sim_step_s=0.005)
    pause = Once(lambda: setattr(bus, "paused", True), lambda: setattr(bus, "paused", False), 400)
    safety = {"stale_feedback_s": 0.1, "following_error_rad": 0.06}
    with loop(bus, tmp_path, VirtualTickClock(HZ), safety=safety) as controller:
        run = run_with(controller, tmp_path, pause)
        faults = controller.snapshot().faults
    assert run.state == "aborted" and "stale feedback" in run.reason
    assert [(f.source, f.kind) for f in faults] == [("bus", "stale feedback")]
    assert "the simulator's time did not advance for 0.1" in faults[0].reason
    assert not run.stats["health"]["ok"]


@pytest.mark.slow  # a real-time run of seconds
def test_a_real_time_loop_starved_by_a_slow_read_is_flagged(tmp_path):
    bus = FakeBus(sim_step_s=0.005)
    slow = Once(
        lambda: setattr(bus, "read_delay_s", 0.06), lambda: setattr(bus, "read_delay_s", 0), 1
    )
    with loop(bus, tmp_path) as controller:
        run = run_with(controller, tmp_path, slow)
    health = run.stats["health"]
    assert not health["ok"] and health["longest_gap_ms"] >= 60.0
    assert any("the loop paused" in r for r in health["reasons"])


@pytest.mark.slow  # starts the MuJoCo twin in its own process
def test_a_run_on_the_real_simulator_paused_mid_run_is_flagged(tmp_path):
    from hardware.sim import ProcessSimBus, SimBusConfig

    bus = ProcessSimBus(SimBusConfig(torque_on_at_start=True))
    bus.connect()
    try:
        pause = Once(lambda: bus.pause(True), lambda: bus.pause(False), 20)
        with loop(bus, tmp_path) as controller:
            run = run_with(controller, tmp_path, pause)
    finally:
        bus.disconnect()
    health = run.stats["health"]
    assert not health["ok"] and health["longest_stale_ms"] >= 50.0, health
    assert any("the simulator's time did not advance" in r for r in health["reasons"])
    assert "following" not in (run.reason or "")
