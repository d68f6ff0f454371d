"""Feedback freshness and the tick's own timing: the figures a run's health is made of.

The freshness detector on hand-made reads (a simulator's time that stands still, a reading
frozen while the command moves), and TickClock on a virtual clock with known stalls and
work times."""

from __future__ import annotations

import numpy as np
import pytest

from app.control.safety import STALE_MOTION_RAD, FeedbackFreshness
from hardware.bus import JointState
from tests.support.ticks import VirtualTickClock


def read(position, sim_time_s=None, current=0.0) -> JointState:
    return JointState(
        position_rad=np.full(3, float(position)),
        velocity_rad_s=np.zeros(3),
        current_a=np.full(3, current),
        voltage_v=np.full(3, 12.0),
        temperature_c=np.full(3, 30.0),
        pwm=np.zeros(3),
        moving=np.zeros(3, dtype=bool),
        hardware_errors=((), (), ()),
        stamp_s=0.0,
        sim_time_s=sim_time_s,
    )


def test_a_simulator_state_is_stale_exactly_when_its_time_did_not_advance():
    fresh = FeedbackFreshness(limit_s=0.5)
    sim_times = [0.0, 0.002, 0.004, 0.004, 0.004, 0.004, 0.010, 0.010]
    stale = [fresh.update(0.005 * k, read(0.1, t), None) for k, t in enumerate(sim_times)]
    assert stale == [False, False, False, True, True, True, False, True]
    assert fresh.certain and fresh.age_s == pytest.approx(0.005)


def test_stale_age_counts_from_the_last_fresh_read_and_faults_past_the_limit():
    fresh = FeedbackFreshness(limit_s=0.1)
    command = np.full(3, 0.1)
    fresh.update(0.0, read(0.1, 1.0), command)
    for k in range(1, 21):  # 20 reads of the same state, 5 ms apart, the command moving on
        fresh.update(0.005 * k, read(0.1, 1.0), command + 0.002 * k)
        fault = fresh.fault(0.005 * k)
        assert (fault is not None) == (fresh.age_s > 0.1)
    assert fresh.age_s == pytest.approx(0.1) and fault is None  # at the limit: not over
    fresh.update(0.105, read(0.1, 1.0), command + 0.042)
    fault = fresh.fault(0.105)
    assert fault is not None and fault.kind == "stale feedback" and fault.source == "bus"
    assert "did not advance for 0.10 s" in fault.reason and "lag" not in fault.reason.split(";")[0]
    fresh.reset()
    assert fresh.update(0.2, read(0.1, 1.0), None) is False  # no earlier state to repeat


def test_a_frozen_simulator_holding_a_still_arm_is_stale_but_never_faults():
    fresh = FeedbackFreshness(limit_s=0.1)
    command = np.full(3, 0.1)
    fresh.update(0.0, read(0.1, 1.0), command)
    for k in range(1, 200):  # a second of the same state; the command moves less than the margin
        nudge = STALE_MOTION_RAD * min(k, 100) / 100
        assert fresh.update(0.005 * k, read(0.1, 1.0), command + nudge)
        assert fresh.fault(0.005 * k) is None
    assert fresh.age_s > 0.9 and fresh.certain
    fresh.update(1.0, read(0.1, 1.0), command + 2 * STALE_MOTION_RAD)  # now it moves on
    assert fresh.fault(1.0) is not None


def test_a_real_bus_reading_is_stale_only_while_unchanged_and_the_command_moved():
    fresh = FeedbackFreshness(limit_s=0.5)
    command = np.full(3, 0.1)
    assert not fresh.update(0.0, read(0.1), command)
    assert not fresh.update(0.005, read(0.1), command)  # an arm at rest: nothing to say
    step = STALE_MOTION_RAD / 2
    assert not fresh.update(0.010, read(0.1), command + step)  # moved less than the margin
    assert fresh.update(0.015, read(0.1), command + 3 * step)  # moved past it: stale
    assert not fresh.certain and fresh.fault(0.015) is None  # never trips: may be blocked
    assert fresh.age_s == pytest.approx(0.005)  # since the last tick it was still news
    assert not fresh.update(0.020, read(0.11), command + 3 * step)  # it changed: fresh
    assert not fresh.update(0.025, read(0.11, current=0.2), command + 9 * step)


def test_tick_timing_of_an_on_time_loop():
    clock = VirtualTickClock(200.0)
    timings = []
    for _ in range(5):
        clock.wait_next()
        clock.end_tick()
        timings.append(clock.last)
    assert timings[0].gap_s == 0.0  # the first tick has no previous one
    assert [t.gap_s for t in timings[1:]] == pytest.approx([0.005] * 4)
    assert not any(t.overrun or t.skipped or t.lateness_s for t in timings)


def test_a_stall_shows_as_lateness_then_a_missed_slot_then_on_time_again():
    clock = VirtualTickClock(200.0, stalls={3: 0.0123})
    timings = []
    for _ in range(6):
        clock.wait_next()
        clock.end_tick()
        timings.append(clock.last)
    stalled, after, then = timings[2], timings[3], timings[4]
    assert stalled.lateness_s == pytest.approx(0.0123) and not stalled.overrun
    assert stalled.gap_s == pytest.approx(0.0173)
    # its slot (20 ms) went by during the stall: skipped, it runs at once in the next one
    assert after.overrun and after.skipped == 1
    assert after.gap_s == 0.0 and after.lateness_s == pytest.approx(0.0023)
    assert then.gap_s == pytest.approx(0.0027) and not then.overrun  # back on the 30 ms slot


def test_work_that_runs_past_the_next_deadline_is_an_overrun_of_the_next_tick():
    class Working(VirtualTickClock):
        work_s = 0.0

        def end_tick(self) -> None:
            self._virtual += self.work_s
            super().end_tick()

    clock = Working(200.0)
    overruns = []
    for work in (0.001, 0.0049, 0.0062, 0.001, 0.001):
        clock.wait_next()
        overruns.append(clock.last.overrun)
        clock.work_s = work
        clock.end_tick()
    # the 6.2 ms tick (the third) ran 1.2 ms into the fourth's slot
    assert overruns == [False, False, False, True, False]
    assert clock.last.lateness_s == pytest.approx(0.0)
