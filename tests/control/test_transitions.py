"""The controller's state machine on a LoopState and a fake bus: no thread, no HTTP, no sim.

One table row per transition (torque, e-stop in each mode, reset, faults, source hand-over,
refusals): a starting state, one command, and what must hold after it, including exactly
which calls reached the bus. Then the tick itself, driven by Controller.step() on a
controller that was never started.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any
from unittest.mock import ANY

import numpy as np
import pytest

from app.config import load_settings
from app.control import commands, contact_commands
from app.control.commands import CommandContext
from app.control.contact import ContactMonitor
from app.control.controller import Controller
from app.control.errors import MotionRefused
from app.control.loop_state import LoopState
from app.control.press import PressSource
from app.control.sources import JogSource, MoveSource, Setpoint
from app.control.state import ContactReading, Fault
from app.control.touch import TouchSource
from tests.support.fake_bus import HOME_M, HOME_RAD, NO_ERRORS, FakeBus

SETTINGS = load_settings()
CTX = {
    "hold": CommandContext.from_settings(SETTINGS),
    "release": dataclasses.replace(CommandContext.from_settings(SETTINGS), estop_action="release"),
}
ROBOT = CTX["hold"].robot
SERVO_2_OVERLOAD = ((), ("overload",), ())
FAULT = Fault("following", "joint 2 lags its command")


class RunSource:
    """A stand-in for a planned run (sinusoid, chirp): asks the loop to hold where it is."""

    def __init__(self, name: str = "sinusoid", fault: str | None = None) -> None:
        self.name, self.fault = name, fault

    def next(self, dt_s: float) -> Setpoint:
        return Setpoint(fault=self.fault)


OTHER_RUN = RunSource("chirp")  # the source a command hands over (or fails to stop)


@dataclass(frozen=True)
class Given:
    """The state before the command: read the robot, torque, e-stop, a fault, a source."""

    read: bool = True
    torque: bool = False
    estopped: bool = False
    faulted: bool = False
    source: str | None = None  # "jog", "move" or "run"
    errors: tuple[tuple[str, ...], ...] = NO_ERRORS
    estop_action: str = "hold"
    bus_fails: bool = False
    estimate: bool = False  # a contact force estimate (a valid one, 0 N) on this robot


def arrange(given: Given) -> tuple[LoopState, CommandContext, FakeBus]:
    ctx = CTX[given.estop_action]
    state = LoopState.initial(SETTINGS.safety, ctx.period_s)
    bus = FakeBus(given.errors)
    if given.read:
        state.joints = bus.read_state()
        state.point_m = ROBOT.fk(state.joints.position_rad).points
    if given.torque:
        state.torque = True
        state.commanded_rad = np.array(HOME_RAD)
        state.commanded_point_m = ROBOT.fk(state.commanded_rad).points
    state.estopped = given.estopped
    if given.faulted:
        state.faults.append(FAULT)
    if given.source == "jog":
        state.source = JogSource(HOME_M, ctx.jog_limits, ctx.period_s)
        state.source.set_target(HOME_M + [0.01, 0, 0])
        state.goal_m = HOME_M + [0.01, 0, 0]
    elif given.source == "move":
        state.source = MoveSource(HOME_M, HOME_M + [0, 0.01, 0], ctx.jog_limits, None, False)
    elif given.source == "run":
        state.source = RunSource()
    elif given.source == "touch":
        state.source = TouchSource(HOME_M, [0, 0, -1], 0.01, 2.0, 0.8, 0.02)
    elif given.source == "press":
        state.source = PressSource(None, HOME_M, [0, 0, -1], 2.0, 0.01, 0.02)
    if given.estimate:
        state.contact_monitor = ContactMonitor(ZeroForce(), SETTINGS.contact)
        state.contact = ContactReading(np.zeros(3), np.full(3, 0.1), True, None)
    bus.fail_reads = bus.fail_writes = given.bus_fails
    return state, ctx, bus


class ZeroForce:
    """A force estimator that reads no force."""

    def estimate(self, joints, **_):
        return ContactReading(np.zeros(3), np.full(3, 0.1), True, None)


@dataclass(frozen=True)
class Then:
    """What must hold after the command (``refused``: a regex of the MotionRefused)."""

    mode: str
    torque: bool
    calls: tuple = ()
    result: Any = field(default_factory=lambda: ANY)  # ANY: not checked
    refused: str | None = None
    faults: int = 0
    same_source: bool | None = None  # the active source object is (not) the one before
    warning: str | None = None
    notice: str | None = None  # checked when given


Command = Callable[[LoopState, CommandContext, FakeBus], Any]
GOAL = HOME_M + [0.0, 0.02, -0.01]
HOLD = (("write_goal", HOME_RAD),)
RELEASE = (("torque", False),)
REBOOT_2 = (("reboot", (2,)),)
ON = {"torque": True}
estop: Command = commands.estop_now
reset: Command = commands.reset_now


def torque_on(state: LoopState, ctx: CommandContext, bus: FakeBus) -> bool:
    return commands.torque_to(state, ctx, bus, True)


def torque_on_swung_past_the_limits(state: LoopState, ctx: CommandContext, bus: FakeBus) -> bool:
    bus.position = np.full(3, 2.128)  # 122 deg: a relaxed arm swinging past its limits
    state.joints = bus.read_state()
    return commands.torque_to(state, ctx, bus, True)


def torque_off(state: LoopState, ctx: CommandContext, bus: FakeBus) -> bool:
    return commands.torque_to(state, ctx, bus, False)


def jog(state: LoopState, ctx: CommandContext, bus: FakeBus) -> list[float]:
    return commands.jog_to(state, ctx, GOAL)


def jog_up(state: LoopState, ctx: CommandContext, bus: FakeBus) -> list[float]:
    return commands.jog_by(state, ctx, np.array([0.0, 0.0, 0.01]))


def move(state: LoopState, ctx: CommandContext, bus: FakeBus) -> dict:
    return commands.move(state, ctx, GOAL, None, False)


def move_joints(state: LoopState, ctx: CommandContext, bus: FakeBus) -> dict:
    return commands.move(state, ctx, np.array(HOME_RAD) + 0.05, 0.5, True)


def run(state: LoopState, ctx: CommandContext, bus: FakeBus) -> str:
    return commands.run_source(state, OTHER_RUN, HOME_M, 2e-3)


def run_moved(state: LoopState, ctx: CommandContext, bus: FakeBus) -> str:
    return commands.run_source(state, OTHER_RUN, HOME_M + 0.01, 2e-3)  # 17.3 mm away


def stop_other(state: LoopState, ctx: CommandContext, bus: FakeBus) -> bool:
    return commands.stop_source(state, OTHER_RUN)


def stop_active(state: LoopState, ctx: CommandContext, bus: FakeBus) -> bool:
    assert state.source is not None
    return commands.stop_source(state, state.source)


def fault(state: LoopState, ctx: CommandContext, bus: FakeBus) -> None:
    commands.record_fault(state, FAULT)


def touch(state: LoopState, ctx: CommandContext, bus: FakeBus) -> str:
    return contact_commands.touch(state, ctx, SETTINGS.contact, [0, 0, -1])["end_m"][2]


def press(state: LoopState, ctx: CommandContext, bus: FakeBus) -> bool:
    return "source_id" in contact_commands.press(state, ctx, SETTINGS.contact, [0, 0, -1], 2.0)


def settle(state: LoopState, bus: FakeBus, joints_rad) -> None:
    """The arm moves without a command (sags under load, falls with torque off); re-read."""
    bus.position = np.array(joints_rad, dtype=np.float64)
    state.joints = bus.read_state()
    state.point_m = ROBOT.fk(state.joints.position_rad).points


SAG_RAD = 0.004  # ~1 mm lower at HOME: the measured sag of the simulated arm per e-stop
FALLEN_M = np.array([-0.012, 0.021, -0.33])  # relaxed, 11 cm below HOME; inside the gate
HANG_RAD = tuple(float(q) for q in ROBOT.ik(FALLEN_M).joints)
HANG_M = ROBOT.fk(np.array(HANG_RAD)).points


def estop_reset_x4(state: LoopState, ctx: CommandContext, bus: FakeBus) -> tuple:
    for _ in range(4):
        settle(state, bus, state.commanded_rad + SAG_RAD)  # the servo sags below its goal
        commands.estop_now(state, ctx, bus)
        commands.reset_now(state, ctx, bus)
    return (*state.commanded_rad, *state.goal_m)


def jog_after_torque_cycle(state: LoopState, ctx: CommandContext, bus: FakeBus) -> list:
    commands.torque_to(state, ctx, bus, False)
    settle(state, bus, HANG_RAD)  # relaxed, the arm falls and hangs
    commands.torque_to(state, ctx, bus, True)
    return commands.jog_by(state, ctx, np.array([0.005, 0.0, 0.0]))


def estop_during_jog_goal(state: LoopState, ctx: CommandContext, bus: FakeBus) -> list:
    commands.estop_now(state, ctx, bus)
    return state.goal_m.tolist()


def bus_down_twice(state: LoopState, ctx: CommandContext, bus: FakeBus) -> int:
    for n in (3, 4):  # the text counts the reads; the cause stays the same
        commands.record_fault(state, Fault("bus", f"{n} reads failed", kind="reads failed"))
    return state.faults[-1].count


# fmt: off
TABLE = [  # given, command, then: one row per transition
    # torque
    pytest.param(
        Given(), torque_on, Then("idle", True, HOLD + (("torque", True),), True),
        id="torque on: holds where it is, then enables",
    ),
    pytest.param(
        Given(), torque_on_swung_past_the_limits,
        Then("idle", False, (), refused="joint 1 is at 121.9 deg, outside its limits .* by more"),
        id="torque on refused while the relaxed arm is past its joint limits",
    ),
    pytest.param(
        Given(**ON, source="jog"), torque_off, Then("idle", False, RELEASE, False),
        id="torque off stops a jog",
    ),
    pytest.param(
        Given(**ON, source="run"), torque_off, Then("idle", False, RELEASE, False),
        id="torque off stops a run",
    ),
    pytest.param(
        Given(read=False), torque_on, Then("idle", False, refused="no joint state"),
        id="torque on before any read: refused",
    ),
    pytest.param(
        Given(estopped=True), torque_on, Then("estop", False, refused="e-stop"),
        id="torque on while e-stopped: refused",
    ),
    pytest.param(
        Given(faulted=True), torque_on, Then("fault", False, refused="fault: joint 2", faults=1),
        id="torque on while faulted: refused",
    ),
    # e-stop, in each mode
    pytest.param(
        Given(**ON, source="move"), estop, Then("estop", True, HOLD, "hold"),
        id="e-stop (hold) during a move: holds, torque stays on",
    ),
    pytest.param(
        Given(**ON, source="jog", estop_action="release"),
        estop,
        Then("estop", False, RELEASE, "release"),
        id="e-stop (release) during a jog: torque off",
    ),
    pytest.param(
        Given(**ON, source="run", estop_action="release"),
        estop,
        Then("estop", False, RELEASE, "release"),
        id="e-stop (release) during a run",
    ),
    pytest.param(
        Given(read=False), estop, Then("estop", False, RELEASE, "hold"),
        id="e-stop (hold) before any read: releases",
    ),
    pytest.param(
        Given(**ON, source="jog", bus_fails=True),
        estop,
        Then("estop", True, (), "hold", warning="e-stop could not reach"),
        id="e-stop with a silent bus: still e-stopped, says so",
    ),
    pytest.param(
        Given(**ON, faulted=True), estop, Then("estop", True, HOLD, "hold", faults=1),
        id="e-stop while faulted: e-stop shows first",
    ),
    pytest.param(
        Given(**ON, source="jog"), estop_during_jog_goal,
        Then("estop", True, HOLD, pytest.approx(list(HOME_M))),
        id="e-stop: goal is the held point, not the jog's old target",
    ),
    pytest.param(
        Given(**ON), estop_reset_x4,
        Then("idle", True, HOLD * 4, pytest.approx((*HOME_RAD, *HOME_M))),
        id="e-stop / reset x4 with a sagging arm: the commanded joints do not ratchet",
    ),
    # reset
    pytest.param(
        Given(**ON, estopped=True), reset, Then("idle", True, (), {"rebooted": []}),
        id="reset after a hold e-stop: torque stays on",
    ),
    pytest.param(
        Given(**ON, faulted=True), reset, Then("idle", True, (), {"rebooted": []}),
        id="reset a fault with no servo errors: nothing rebooted",
    ),
    pytest.param(
        Given(**ON, faulted=True, errors=SERVO_2_OVERLOAD),
        reset,
        Then("idle", False, REBOOT_2, {"rebooted": [2]}),
        id="reset with servo 2 in error: reboots it, torque off",
    ),
    pytest.param(
        Given(**ON, estopped=True, faulted=True, errors=SERVO_2_OVERLOAD),
        reset,
        Then("idle", False, REBOOT_2, {"rebooted": [2]}),
        id="reset e-stop and fault together",
    ),
    pytest.param(
        Given(**ON, source="jog"), reset, Then("idle", True, (), {"rebooted": []}),
        id="reset with nothing wrong stops the source",
    ),
    # faults during motion
    pytest.param(
        Given(**ON, source="jog"), fault, Then("fault", True, faults=1),
        id="fault during a jog: source dropped",
    ),
    pytest.param(
        Given(**ON, source="move"), fault, Then("fault", True, faults=1),
        id="fault during a move: source dropped",
    ),
    pytest.param(
        Given(**ON, source="run"), fault, Then("fault", True, faults=1),
        id="fault during a run: source dropped",
    ),
    pytest.param(
        Given(**ON, faulted=True), fault, Then("fault", True, faults=1),
        id="the same fault twice is recorded once",
    ),
    pytest.param(
        Given(**ON, faulted=True), bus_down_twice, Then("fault", True, result=2, faults=2),
        id="the same cause with a new text: counted, not added",
    ),
    # motion refused
    pytest.param(
        Given(), jog, Then("idle", False, refused="torque is off"),
        id="jog with torque off: refused",
    ),
    pytest.param(
        Given(**ON, estopped=True), jog, Then("estop", True, refused="e-stop"),
        id="jog while e-stopped: refused",
    ),
    pytest.param(
        Given(**ON, faulted=True), move, Then("fault", True, refused="fault", faults=1),
        id="move while faulted: refused",
    ),
    pytest.param(
        Given(), move_joints, Then("idle", False, refused="torque is off"),
        id="joint move with torque off: refused",
    ),
    pytest.param(
        Given(**ON, estopped=True, source=None), run, Then("estop", True, refused="e-stop"),
        id="run while e-stopped: refused",
    ),
    pytest.param(
        Given(**ON, faulted=True), run, Then("fault", True, refused="fault", faults=1),
        id="run while faulted: refused",
    ),
    pytest.param(
        Given(**ON, source="run"),
        run_moved,
        Then("sinusoid", True, refused="moved 17.3 mm", same_source=True),
        id="run refused: the robot moved since the plan",
    ),
    # motion started, and one source replacing another
    pytest.param(
        Given(**ON), jog, Then("jog", True, (), GOAL.tolist()),
        id="jog from idle",
    ),
    pytest.param(
        Given(**ON, source="jog"), jog_after_torque_cycle,
        Then("jog", True, RELEASE + (("write_goal", HANG_RAD), ("torque", True)),
             pytest.approx(list(HANG_M + [0.005, 0, 0])), same_source=False,
             notice="starting from the measured position"),
        id="jog after torque off / on: from the measured point, by the step only",
    ),
    pytest.param(
        Given(**ON, source="jog"),
        jog_up,
        Then("jog", True, (), pytest.approx([0.01, 0.0, -0.21]), same_source=True),
        id="jog by a step retargets the active jog",
    ),
    pytest.param(
        Given(**ON, source="move"), jog, Then("jog", True, same_source=False),
        id="a jog replaces a move",
    ),
    pytest.param(
        Given(**ON, source="run"), jog, Then("jog", True, same_source=False),
        id="a jog replaces a run",
    ),
    pytest.param(
        Given(**ON, source="jog"), move, Then("move", True, same_source=False),
        id="a move replaces a jog",
    ),
    pytest.param(
        Given(**ON, source="jog"), move_joints, Then("move-joints", True, same_source=False),
        id="a joint move replaces a jog",
    ),
    pytest.param(
        Given(**ON, source="move"), run, Then("chirp", True, (), "chirp", same_source=False),
        id="a run replaces a move",
    ),
    pytest.param(
        Given(**ON, source="run"), run, Then("chirp", True, (), "chirp", same_source=False),
        id="a run replaces another run",
    ),
    pytest.param(
        Given(**ON, source="run"), stop_other, Then("sinusoid", True, (), False, same_source=True),
        id="stop a source that is not the active one: nothing",
    ),
    pytest.param(
        Given(**ON, source="run"), stop_active, Then("idle", True, (), True),
        id="stop the active source: holds",
    ),
    # contact (issue 33): touch and press start only with a force estimate and authority
    pytest.param(
        Given(**ON, estimate=True), touch, Then("touch", True, (), pytest.approx(HOME_M[2] - 0.05)),
        id="touch from idle: down the default travel",
    ),
    pytest.param(
        Given(**ON), touch, Then("idle", True, (), refused="no contact force estimate"),
        id="touch without a force estimate: refused",
    ),
    pytest.param(
        Given(estimate=True), touch, Then("idle", False, (), refused="torque is off"),
        id="touch with torque off: refused",
    ),
    pytest.param(
        Given(**ON, estimate=True, faulted=True), press,
        Then("fault", True, (), refused="fault: joint 2", faults=1),
        id="press while faulted: refused",
    ),
    pytest.param(
        Given(**ON, estimate=True, source="jog"), press,
        Then("press", True, (), True, same_source=False),
        id="a press replaces a jog",
    ),
    pytest.param(
        Given(**ON, source="touch"), estop, Then("estop", True, HOLD, "hold"),
        id="e-stop (hold) during a touch: holds",
    ),
    pytest.param(
        Given(**ON, source="press", estop_action="release"), estop,
        Then("estop", False, RELEASE, "release"),
        id="e-stop (release) during a press: torque off",
    ),
    pytest.param(
        Given(**ON, source="press"), torque_off, Then("idle", False, RELEASE, False),
        id="torque off stops a press",
    ),
    pytest.param(
        Given(**ON, source="touch"), fault, Then("fault", True, (), None, faults=1),
        id="fault during a touch: source dropped",
    ),
]
# fmt: on


@pytest.mark.parametrize(("given", "command", "then"), TABLE)
def test_transition(given: Given, command: Command, then: Then) -> None:
    state, ctx, bus = arrange(given)
    before = state.source
    if then.refused is not None:
        with pytest.raises(MotionRefused, match=then.refused):
            command(state, ctx, bus)
    else:
        assert command(state, ctx, bus) == then.result
    assert (state.mode, state.torque) == (then.mode, then.torque)
    assert state.estopped == (then.mode == "estop")
    assert len(state.faults) == then.faults
    if then.mode in ("estop", "fault"):
        assert state.source is None, "a source survived the stop"
    assert tuple(bus.calls) == then.calls
    if then.same_source is not None:
        assert (state.source is before) == then.same_source
    if then.warning is None:
        assert state.warning is None
    else:
        assert then.warning in state.warning
    if then.notice is not None:
        assert then.notice in (state.notice or "")


def test_reset_clears_the_safety_detectors() -> None:
    state, ctx, bus = arrange(Given(**ON, faulted=True))
    state.misses.miss()
    state.following.check(0.0, np.zeros(3), np.ones(3))  # over the limit since t = 0
    commands.reset_now(state, ctx, bus)
    assert state.misses.consecutive == 0
    assert state.following.check(10.0, np.zeros(3), np.ones(3)) is None  # the timer restarted


def test_torque_on_commands_the_measured_pose() -> None:
    state, ctx, bus = arrange(Given())
    commands.torque_to(state, ctx, bus, True)
    np.testing.assert_array_equal(state.commanded_rad, HOME_RAD)
    np.testing.assert_allclose(state.commanded_point_m, HOME_M, atol=1e-9)


@pytest.mark.parametrize("torque", [False, True])
@pytest.mark.parametrize("estopped", [False, True])
@pytest.mark.parametrize("faulted", [False, True])
def test_motion_is_allowed_exactly_when_not_refused(torque, estopped, faulted) -> None:
    state, _, _ = arrange(Given(torque=torque, estopped=estopped, faulted=faulted))
    try:
        commands.require_motion(state)
        refused = False
    except MotionRefused:
        refused = True
    expected = torque and not estopped and not faulted
    assert commands.motion_allowed(state) == (not refused) == expected


# ---- the tick, without the thread ----
def controller(bus: FakeBus, **overrides) -> Controller:
    return Controller(load_settings(**overrides) if overrides else SETTINGS, bus, "fake")


def writes(bus: FakeBus) -> int:
    return sum(call[0] == "write_goal" for call in bus.calls)


def test_a_tick_reads_publishes_and_writes_nothing_when_idle() -> None:
    bus = FakeBus()
    loop = controller(bus)
    loop.step()
    snap = loop.snapshot()
    assert (snap.tick, snap.mode, snap.torque) == (1, "idle", False)
    np.testing.assert_array_equal(snap.joints_measured_rad, HOME_RAD)
    np.testing.assert_allclose(snap.point_measured_m, HOME_M, atol=1e-9)
    assert bus.calls == []


@pytest.mark.parametrize("late", [1, 20])
def test_a_move_ends_on_its_goal_even_when_ticks_come_late(late) -> None:
    """Ticks ``late`` periods apart: the move's source advances by the time elapsed but the
    joint speed limit lets the joints move one period's worth a tick, so the source ends
    while they are short of its end; the loop then steps on to it (a move stopped short
    once, on a loaded machine)."""
    bus = FakeBus()
    loop = controller(bus)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    target = HOME_M + np.array([0.0, 0.0, -0.04])
    commands.move(loop.state, loop.ctx, target, 0.2, joint_space=False)
    short = []  # how far the command is from the target once the source has ended
    for _ in range(400):
        loop.state.dt_s = late * loop.period_s
        loop.step()
        if loop.state.source is None:
            short.append(float(np.linalg.norm(loop.state.commanded_point_m - target)))
            if short[-1] < 5e-6:  # the move's source ends within ruckig's tolerance (~1 um)
                break
    assert short and short[-1] < 5e-6, short[-3:]
    assert loop.snapshot().mode == "idle"
    if late > 1:  # the limit did hold the joints back when the source ended
        assert short[0] > 1e-3, short[:3]


@pytest.mark.parametrize("past_rad", [0.001, 0.09, 0.19])
def test_torque_on_a_relaxed_arm_resting_just_past_a_limit_steps_it_back_inside(past_rad):
    """The twin's relaxed arm rests near its joint limits, at times past one (95 and 100 deg
    against 94.5): torque on holds it where it is (nothing jumps), then the loop steps it
    inside at the joint speed limit, rather than refusing torque for ever."""
    bus = FakeBus()
    loop = controller(bus)
    high = loop.gate.joint_max_rad[1]
    bus.position = np.array([HOME_RAD[0], high + past_rad, HOME_RAD[2]])
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    assert bus.calls[-2:] == [("write_goal", tuple(bus.position)), ("torque", True)]
    inside = np.array([HOME_RAD[0], high, HOME_RAD[2]])
    np.testing.assert_allclose(loop.state.goal_m, ROBOT.fk(inside).points, atol=1e-12)
    steps = []
    for _ in range(100):
        loop.step()
        steps.append(bus.calls[-1][1][1] if bus.calls[-1][0] == "write_goal" else None)
        if loop.state.settle_rad is None:
            break
    np.testing.assert_allclose(loop.state.commanded_rad, inside, atol=0)
    moves = np.abs(np.diff([high + past_rad, *[v for v in steps if v is not None]]))
    assert moves.max() <= loop.gate.max_step_rad * (1 + 1e-9)  # at the joint speed limit
    assert loop.snapshot().mode == "idle" and not loop.snapshot().faults


def test_a_jog_is_ticked_towards_its_goal_and_a_servo_error_stops_it() -> None:
    bus = FakeBus()
    loop = controller(bus)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    commands.jog_to(loop.state, loop.ctx, GOAL)
    for _ in range(10):
        loop.step()
    assert loop.snapshot().mode == "jog" and writes(bus) == 1 + 10
    moved = np.linalg.norm(loop.snapshot().point_commanded_m - HOME_M)
    assert 0 < moved < np.linalg.norm(GOAL - HOME_M)
    bus.errors, before = SERVO_2_OVERLOAD, writes(bus)
    loop.step()
    snap = loop.snapshot()
    assert snap.mode == "fault" and writes(bus) == before  # nothing written once faulted
    assert [f.servo_id for f in snap.faults] == [2] and "overload" in snap.faults[0].reason
    assert commands.reset_now(loop.state, loop.ctx, bus) == {"rebooted": [2]}
    loop.step()
    snap = loop.snapshot()
    assert (snap.mode, snap.torque, snap.faults) == ("idle", False, ())


@pytest.mark.parametrize("stopped", ["torque", "estopped", "faults"])
def test_the_tick_writes_nothing_unless_motion_is_allowed(stopped: str) -> None:
    """Defence in depth: even a source left behind by a bug does not reach the servos."""
    bus = FakeBus()
    loop = controller(bus)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    commands.jog_to(loop.state, loop.ctx, GOAL)
    setattr(loop.state, stopped, {"torque": False, "estopped": True, "faults": [FAULT]}[stopped])
    before = writes(bus)
    for _ in range(5):
        loop.step()
    assert writes(bus) == before


def test_a_move_runs_to_its_end_and_the_loop_goes_idle() -> None:
    bus = FakeBus()
    loop = controller(bus)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    result = commands.move(loop.state, loop.ctx, GOAL, None, False)
    ticks = int(np.ceil(result["duration_s"] / loop.period_s)) + 1
    for _ in range(ticks):
        loop.step()
    assert loop.snapshot().mode == "idle"
    np.testing.assert_allclose(loop.snapshot().point_measured_m, GOAL, atol=1e-6)


def test_a_run_that_reports_a_fault_stops_with_a_source_fault() -> None:
    bus = FakeBus()
    loop = controller(bus)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    commands.run_source(loop.state, RunSource(fault="the drone link dropped"), HOME_M, 2e-3)
    loop.step()
    snap = loop.snapshot()
    assert snap.mode == "fault" and snap.faults[0].source == "source"
    assert "sinusoid: the drone link dropped" in snap.faults[0].reason


def test_reads_failing_max_missed_reads_times_fault_the_bus() -> None:
    bus = FakeBus()
    loop = controller(bus, safety={"max_missed_reads": 3})
    loop.step()
    bus.fail_reads = True
    loop.step()
    loop.step()
    assert loop.snapshot().mode == "idle" and loop.snapshot().missed_reads == 2
    loop.step()
    snap = loop.snapshot()
    assert snap.mode == "fault" and snap.faults[0].source == "bus"
    assert "3 reads failed" in snap.faults[0].reason


def test_a_stuck_servo_trips_the_following_error() -> None:
    bus = FakeBus()
    loop = controller(bus, safety={"following_error_rad": 0.05, "following_error_time_s": 0.0})
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    commands.move(loop.state, loop.ctx, np.array(HOME_RAD) + 0.3, None, True)
    bus.stuck = True
    for _ in range(200):
        loop.step()
        if loop.snapshot().faults:
            break
    snap = loop.snapshot()
    assert snap.mode == "fault" and snap.faults[0].source == "following"


def test_estop_without_the_loop_acts_at_once_and_other_commands_are_refused() -> None:
    bus = FakeBus()
    loop = controller(bus)
    loop.step()
    assert loop.estop().result(timeout=0) == "hold"
    assert loop.state.estopped and bus.calls == [("write_goal", HOME_RAD)]
    with pytest.raises(RuntimeError, match="not running"):
        loop.set_torque(True).result(timeout=0)


class Pushing:
    """A force estimator that reads ``force_n`` along -z, or an invalid estimate."""

    def __init__(self, force_n: float, valid: bool = True) -> None:
        self.force_n, self.valid = force_n, valid

    def estimate(self, joints, **_):
        if not self.valid:
            return ContactReading(reason="current of joint 3 not read")
        return ContactReading(np.array([0.0, 0.0, -self.force_n]), np.full(3, 0.1), True, None)


@pytest.mark.parametrize(
    ("source", "estimator", "collision_stop", "kind"),
    [
        ("touch", Pushing(16.0), False, "force limit"),
        ("press", Pushing(0.0, valid=False), False, "estimate"),
        ("move", Pushing(7.0), True, "collision"),
        ("move", Pushing(7.0), False, None),  # force-limited motion off: a move goes on
        ("touch", Pushing(14.0), False, None),  # under the limit: the touch goes on
        ("move", Pushing(0.0, valid=False), False, None),  # no estimate needed to move
    ],
)
def test_a_tick_past_a_contact_limit_faults_and_holds_where_measured(
    source, estimator, collision_stop, kind
) -> None:
    bus = FakeBus()
    loop = controller(bus, contact={"collision_stop": collision_stop})
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    loop.state.contact_monitor = ContactMonitor(estimator, loop.settings.contact)
    if source == "move":
        commands.move(loop.state, loop.ctx, HOME_M + np.array([0.0, 0.0, -0.04]), 0.5, False)
    else:
        loop.state.source = arrange(Given(**ON, source=source))[0].source
    bus.position = np.array(HOME_RAD) + 0.001  # the arm measured a little off its command
    bus.calls.clear()
    loop.step()
    if kind is None:
        assert loop.state.mode != "fault" and loop.state.source is not None
        return
    assert loop.state.mode == "fault" and loop.state.faults[0].kind == kind
    assert loop.state.source is None
    # the one goal written: the joints where they were measured (nothing pushes further)
    goals = [call[1] for call in bus.calls if call[0] == "write_goal"]
    assert len(goals) == 1
    np.testing.assert_allclose(goals[0], bus.position, atol=1e-12)
    loop.step()
    assert writes(bus) == 1  # and nothing after it
