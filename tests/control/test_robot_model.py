"""The robot model the controller uses, replaced by a geometry calibration's apply
(app/control/model.py, ``Controller.use_model``): a fake bus, no thread.

What must hold: nothing moves at the swap (the servos keep their goal ticks); from then
on the loop's FK, IK and gate are the new robot's (a goal outside its workspace is refused
though the nominal robot reaches it, and the other way round); a goal checked against the
old model is not acted on under the new one; while a motion runs nothing changes; and the
symmetric robot stays as it was without an apply.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.config import load_settings
from app.control import commands
from app.control.controller import Controller
from app.control.errors import GoalRejected, MotionRefused
from app.control.force import force_estimator
from app.control.sources import MoveSource
from kinematics import THESIS_DELTA, PerLegRotaryDelta, RotaryDelta
from tests.support.fake_bus import HOME_RAD, FakeBus

SETTINGS = load_settings()
SHORT_RODS = PerLegRotaryDelta.from_symmetric(THESIS_DELTA, l=(0.2410, 0.2415, 0.2405))
LONG_RODS = PerLegRotaryDelta.from_symmetric(THESIS_DELTA, l=(0.2450, 0.2445, 0.2455))
OFFSETS = np.radians([2.0, -3.0, 1.5])
CENTRE_M = np.array([0.0, 0.0, -0.24])
FAR_BELOW_M = np.array([0.0, 0.0, -1.0])


class Clock:
    now = 1000.0

    def __call__(self) -> float:
        return self.now


class Stepped(Controller):
    """A controller whose commands queue as on a running loop; the test steps it."""

    @property
    def running(self) -> bool:
        return True


def _holding() -> tuple[Stepped, FakeBus, Clock]:
    clock, bus = Clock(), FakeBus()
    loop = Stepped(SETTINGS, bus, "fake", clock=clock)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, loop.joint_bus, True)
    loop.step()
    return loop, bus, clock


def _tick(loop: Controller, clock: Clock, n: int = 1) -> None:
    for _ in range(n):
        clock.now += loop.period_s
        loop.step()


def _apply(loop: Stepped, robot, offsets=(0.0, 0.0, 0.0)):
    future = loop.use_model(robot, offsets, "calibration cal-test")
    loop.step()
    return future.result(timeout=0)


def _bottom(loop: Controller) -> np.ndarray:
    """The deepest point the model in use accepts below the centre, 0.3 mm inside."""
    lowest = loop.gate.nearest(FAR_BELOW_M)
    return lowest + 3e-4 * (CENTRE_M - lowest) / np.linalg.norm(CENTRE_M - lowest)


def test_nothing_moves_at_the_swap_and_the_loop_sees_the_new_robot() -> None:
    loop, bus, clock = _holding()
    written = len(bus.calls)
    model = _apply(loop, SHORT_RODS, OFFSETS)
    assert model.version == 1 and loop.model is model and loop.robot is SHORT_RODS
    assert loop.ctx.gate is model.gate and loop.gate.robot is SHORT_RODS
    _tick(loop, clock, 5)
    snap = loop.snapshot()
    # the servos hold the same ticks: every goal written since is the one held before
    np.testing.assert_allclose(bus.position, HOME_RAD, atol=1e-12)
    assert all(c[0] != "write_goal" or np.allclose(c[1], HOME_RAD) for c in bus.calls[written:])
    joints = np.add(HOME_RAD, OFFSETS)
    np.testing.assert_allclose(snap.joints_measured_rad, joints, atol=1e-12)
    np.testing.assert_allclose(snap.joints_commanded_rad, joints, atol=1e-12)
    # the points are the new robot's FK of those joints, the goal held is the commanded one
    expected = SHORT_RODS.fk(joints).points
    np.testing.assert_allclose(snap.point_measured_m, expected, atol=1e-12)
    np.testing.assert_allclose(snap.point_commanded_m, expected, atol=1e-12)
    np.testing.assert_allclose(snap.goal_m, expected, atol=1e-12)
    assert not np.allclose(expected, THESIS_DELTA.fk(joints).points, atol=1e-4)
    assert not snap.faults and "calibration cal-test" in (snap.notice or "")


def test_a_move_lands_where_the_new_robot_says() -> None:
    loop, bus, clock = _holding()
    _apply(loop, SHORT_RODS, OFFSETS)
    goal = np.array([0.02, -0.01, -0.25])
    loop.move(point=goal, duration_s=0.3)
    _tick(loop, clock, 150)
    joints = SHORT_RODS.ik(goal).joints
    np.testing.assert_allclose(loop.snapshot().joints_measured_rad, joints, atol=1e-9)
    np.testing.assert_allclose(bus.position, joints - OFFSETS, atol=1e-9)  # servo frame
    np.testing.assert_allclose(loop.snapshot().point_measured_m, goal, atol=1e-9)


def test_a_goal_outside_the_fitted_workspace_is_refused_though_the_nominal_reaches_it() -> None:
    loop, _, _ = _holding()
    point = _bottom(loop)  # accepted by the nominal robot (shown by the goal itself)
    loop.gate.solve(loop.gate.check_point(point), np.array(HOME_RAD))
    _apply(loop, SHORT_RODS)
    with pytest.raises(GoalRejected, match="outside the workspace") as refused:
        loop.set_goal(point)
    nearest = refused.value.nearest
    assert nearest is not None and SHORT_RODS.reachable(nearest, margin=loop.gate.margin_m)
    assert np.linalg.norm(nearest - point) > 1e-3  # the rods are 1.5 - 2.5 mm shorter


@pytest.mark.slow
def test_and_the_other_way_round_a_goal_only_the_fitted_robot_reaches_is_accepted() -> None:
    loop, _, clock = _holding()
    nominal = loop.gate
    _apply(loop, LONG_RODS)
    point = _bottom(loop)
    with pytest.raises(GoalRejected, match="outside the workspace"):
        nominal.check_point(point)
    loop.set_goal(point)
    _tick(loop, clock, 400)
    np.testing.assert_allclose(loop.snapshot().point_measured_m, point, atol=1e-9)


@pytest.mark.slow
def test_a_jog_is_clamped_onto_the_fitted_workspace() -> None:
    loop, _, clock = _holding()
    _apply(loop, SHORT_RODS)
    loop.jog(FAR_BELOW_M - loop.snapshot().point_commanded_m)
    loop.step()
    goal = loop.snapshot().goal_m
    # the jog's aim is the fitted workspace's lowest point (with the margin), not the nominal's
    np.testing.assert_allclose(goal, loop.gate.nearest(FAR_BELOW_M), atol=1e-9)
    assert SHORT_RODS.reachable(goal, margin=loop.gate.margin_m - 1e-9)
    assert not SHORT_RODS.reachable(goal + [0, 0, -1e-4], margin=loop.gate.margin_m)
    _tick(loop, clock, 600)
    np.testing.assert_allclose(loop.snapshot().point_measured_m, goal, atol=1e-9)


def test_a_goal_checked_against_the_old_model_is_not_acted_on_under_the_new_one() -> None:
    """The apply is queued first, the goal checked (against the model still in use) and
    queued after it: the goal's command finds another model and is refused."""
    loop, bus, _ = _holding()
    point = _bottom(loop)
    applied = loop.use_model(SHORT_RODS, (0.0, 0.0, 0.0), "calibration cal-test")
    goal = loop.set_goal(point)  # passes the nominal gate, in this thread
    written = len(bus.calls)
    loop.step()
    assert applied.result(timeout=0).version == 1
    with pytest.raises(MotionRefused, match="model changed since this was checked"):
        goal.result(timeout=0)
    assert loop.snapshot().mode == "idle"
    assert all(c[0] != "write_goal" or np.allclose(c[1], HOME_RAD) for c in bus.calls[written:])


def test_a_run_checked_against_the_old_model_does_not_start() -> None:
    loop, _, _ = _holding()
    old = loop.model
    _apply(loop, SHORT_RODS)
    source = MoveSource(
        loop.snapshot().point_commanded_m, CENTRE_M, loop.ctx.jog_limits, 0.5, False
    )
    started = loop.run_source(source, loop.snapshot().point_commanded_m, model=old)
    loop.step()
    with pytest.raises(MotionRefused, match="model changed"):
        started.result(timeout=0)
    assert loop.snapshot().mode == "idle"


def test_refused_while_a_motion_runs_and_nothing_changes() -> None:
    loop, _, clock = _holding()
    loop.move(joints=np.add(HOME_RAD, 0.1), duration_s=1.0)
    _tick(loop, clock)
    future = loop.use_model(SHORT_RODS, OFFSETS, "calibration cal-test")
    loop.step()
    with pytest.raises(MotionRefused, match="rests"):
        future.result(timeout=0)
    assert loop.model.version == 0 and isinstance(loop.robot, RotaryDelta)
    np.testing.assert_array_equal(loop.joint_offsets_rad, 0.0)


def test_the_symmetric_robot_stays_without_a_geometry_apply() -> None:
    """No [robot.legs] and no geometry applied: the thesis robot, as before; joint
    offsets alone do not change the model."""
    loop, _, clock = _holding()
    assert loop.robot == THESIS_DELTA and type(loop.robot) is RotaryDelta
    assert loop.model.version == 0 and loop.model.describe()["kind"] == "symmetric"
    loop.set_joint_offsets(OFFSETS)
    _tick(loop, clock)
    assert loop.robot == THESIS_DELTA and loop.model.version == 0


def test_gravity_compensation_follows_the_new_robot() -> None:
    settings = load_settings(control={"gravity_compensation": True})
    loop = Stepped(settings, FakeBus(), "fake", clock=Clock())
    loop.step()
    before = loop.gravity.offset_rad(np.array(HOME_RAD))
    _apply(loop, SHORT_RODS)
    assert loop.gravity.robot == SHORT_RODS.nominal()
    after = loop.gravity.offset_rad(np.array(HOME_RAD))
    assert np.all(np.isfinite(after)) and not np.array_equal(before, after)


def test_a_jog_that_has_arrived_ends_at_the_apply_and_one_still_going_refuses_it() -> None:
    """A goal (POST /api/goal) is a jog, which holds its point once there: the arm rests,
    so the apply goes, the jog ends and the servos keep their goal. On the way it is
    refused."""
    loop, bus, clock = _holding()
    goal = np.array([0.02, 0.01, -0.25])
    loop.set_goal(goal)
    _tick(loop, clock, 3)
    assert loop.snapshot().mode == "jog"
    future = loop.use_model(SHORT_RODS, (0.0, 0.0, 0.0), "calibration cal-test")
    loop.step()
    with pytest.raises(MotionRefused, match="a jog is running"):
        future.result(timeout=0)
    _tick(loop, clock, 400)  # arrived
    held = bus.position.copy()
    np.testing.assert_allclose(held, THESIS_DELTA.ik(goal).joints, atol=1e-9)
    _apply(loop, SHORT_RODS)
    _tick(loop, clock, 5)
    assert loop.snapshot().mode == "idle" and loop.model.version == 1
    np.testing.assert_array_equal(bus.position, held)  # nothing moved
    np.testing.assert_allclose(loop.snapshot().goal_m, SHORT_RODS.fk(held).points, atol=1e-12)


def test_refused_while_the_arm_still_settles_onto_a_moves_goal() -> None:
    """A move ended with its last joints still ahead (the speed limit held them back: the
    loop steps on to them, state.settle_rad); the arm is still moving."""
    loop, _, _ = _holding()
    loop.state.settle_rad = np.add(HOME_RAD, 0.01)
    future = loop.use_model(SHORT_RODS, OFFSETS, "calibration cal-test")
    loop.step()
    with pytest.raises(MotionRefused, match="still settling"):
        future.result(timeout=0)
    assert loop.model.version == 0
    np.testing.assert_array_equal(loop.joint_offsets_rad, 0.0)


def test_the_force_estimate_takes_the_applied_geometry() -> None:
    """A calibration's geometry reaches the contact force estimate too (its Jacobian and
    dynamics): the estimator's robot is the new model's symmetric mean after the apply."""
    loop, _, _ = _holding()
    monitor = loop.state.contact_monitor
    monitor.estimator = force_estimator(THESIS_DELTA)  # as on a bus that carries the arm
    _apply(loop, LONG_RODS)
    robot = monitor.estimator.robot
    assert isinstance(robot, RotaryDelta)
    assert robot.l == pytest.approx(np.mean([0.2450, 0.2445, 0.2455]))
    assert robot.l != THESIS_DELTA.l
