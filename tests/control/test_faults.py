"""Faults once: one entry per cause with a count and first/last time, in a bounded list.

Driven on a LoopState (record_fault) and on a Controller stepped by hand over a fake bus
whose reads fail, as a bus that went down does tick after tick.
"""

from __future__ import annotations

import numpy as np

from app.config import load_settings
from app.control import commands
from app.control.commands import MAX_FAULT_CAUSES
from app.control.controller import Controller
from app.control.loop_state import LoopState
from app.control.state import Fault
from app.server.api.responses import FaultOut
from tests.support.fake_bus import FakeBus

SETTINGS = load_settings()


def test_the_same_cause_with_changing_text_is_one_entry_counting_up() -> None:
    state = LoopState.initial(SETTINGS.safety, 0.005)
    for n in range(3, 40):
        fault = Fault("bus", f"{n} reads failed: timeout", time_s=0.1 * n, kind="reads failed")
        commands.record_fault(state, fault)
    (only,) = state.faults
    assert only.count == 37 and only.reason == "39 reads failed: timeout"
    out = FaultOut(**only.as_dict())  # the status's strict model accepts it
    assert (out.first_time_s, out.time_s) == (0.30000000000000004, out.first_time_s)
    assert np.isclose(out.last_time_s, 3.9) and out.kind == "reads failed"


def test_different_causes_are_kept_apart() -> None:
    state = LoopState.initial(SETTINGS.safety, 0.005)
    commands.record_fault(state, Fault("servo", "servo 1: overload", 1, 0.0, "hardware"))
    commands.record_fault(state, Fault("servo", "servo 2: overload", 2, 0.0, "hardware"))
    commands.record_fault(state, Fault("bus", "3 reads failed: x", kind="reads failed"))
    commands.record_fault(state, Fault("servo", "servo 1: overload", 1, 1.0, "hardware"))
    assert [(f.source, f.servo_id, f.count) for f in state.faults] == [
        ("servo", 1, 2),
        ("servo", 2, 1),
        ("bus", None, 1),
    ]


def test_the_list_is_bounded_and_counts_what_it_dropped() -> None:
    state = LoopState.initial(SETTINGS.safety, 0.005)
    extra = 7
    for i in range(MAX_FAULT_CAUSES + extra):
        commands.record_fault(state, Fault("loop", f"internal error {i}", time_s=float(i)))
    assert len(state.faults) == MAX_FAULT_CAUSES and state.faults_dropped == extra
    assert state.faults[0].reason == f"internal error {extra}"  # the oldest went first
    snap = state.snapshot(0.0)
    assert snap.faults_dropped == extra
    commands.reset_now(state, commands.CommandContext.from_settings(SETTINGS), FakeBus())
    assert state.faults == [] and state.faults_dropped == 0


def test_a_bus_down_for_many_ticks_is_one_fault_with_a_growing_count() -> None:
    bus = FakeBus()
    loop = Controller(load_settings(safety={"max_missed_reads": 3}), bus, "fake")
    loop.step()
    bus.fail_reads = True
    counts = []
    for _ in range(200):
        loop.step()
        counts.append(sum(f.count for f in loop.snapshot().faults))
    snap = loop.snapshot()
    (fault,) = snap.faults
    assert fault.source == "bus" and fault.kind == "reads failed"
    assert fault.count == 200 - 2  # every tick from the third miss on
    assert "200 reads failed" in fault.reason  # the latest text
    assert counts == sorted(counts) and fault.last_time_s >= fault.first_time_s
    assert snap.faults_dropped == 0
