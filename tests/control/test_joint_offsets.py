"""Joint offsets from calibration, applied by the loop between bus and kinematics
(app/control/joint_offsets.py): a fake bus, no thread."""

from __future__ import annotations

import numpy as np
import pytest

from app.config import load_settings
from app.control import commands
from app.control.controller import Controller
from app.control.errors import MotionRefused
from app.control.joint_offsets import set_offsets
from tests.support.fake_bus import HOME_RAD, FakeBus

SETTINGS = load_settings()
OFFSETS = np.radians([2.0, -3.0, 1.5])


class Clock:
    now = 1000.0

    def __call__(self) -> float:
        return self.now


def _holding() -> tuple[Controller, FakeBus, Clock]:
    clock, bus = Clock(), FakeBus()
    loop = Controller(SETTINGS, bus, "fake", clock=clock)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, loop.joint_bus, True)
    loop.step()
    return loop, bus, clock


def _tick(loop: Controller, clock: Clock, n: int = 1) -> None:
    for _ in range(n):
        clock.now += loop.period_s
        loop.step()


def test_reads_add_the_offsets_and_the_held_goal_stays_the_same_ticks() -> None:
    loop, bus, clock = _holding()
    written = len(bus.calls)
    set_offsets(loop.state, loop.robot, loop.joint_bus, OFFSETS)
    _tick(loop, clock, 5)
    snap = loop.snapshot()
    np.testing.assert_allclose(snap.joints_measured_rad, np.add(HOME_RAD, OFFSETS), atol=1e-12)
    np.testing.assert_allclose(snap.joints_commanded_rad, snap.joints_measured_rad, atol=1e-12)
    np.testing.assert_allclose(bus.position, HOME_RAD, atol=1e-12)  # the arm did not move
    np.testing.assert_allclose(
        snap.point_measured_m, loop.robot.fk(np.add(HOME_RAD, OFFSETS)).points, atol=1e-12
    )
    assert not snap.faults
    assert all(c[0] != "write_goal" or np.allclose(c[1], HOME_RAD) for c in bus.calls[written:])


def test_a_move_goes_where_the_offset_joints_say() -> None:
    loop, bus, clock = _holding()
    set_offsets(loop.state, loop.robot, loop.joint_bus, OFFSETS)
    target = np.add(HOME_RAD, [0.1, 0.05, -0.05])
    commands.move(loop.state, loop.ctx, target, 0.2, True)
    _tick(loop, clock, 200)
    np.testing.assert_allclose(loop.snapshot().joints_measured_rad, target, atol=1e-9)
    np.testing.assert_allclose(bus.position, target - OFFSETS, atol=1e-9)  # servo frame


def test_refused_while_a_motion_runs_and_for_bad_values() -> None:
    loop, _, clock = _holding()
    commands.move(loop.state, loop.ctx, np.add(HOME_RAD, 0.1), 1.0, True)
    _tick(loop, clock)
    with pytest.raises(MotionRefused, match="rests"):
        set_offsets(loop.state, loop.robot, loop.joint_bus, OFFSETS)
    np.testing.assert_array_equal(loop.joint_offsets_rad, 0.0)
    with pytest.raises(ValueError, match="joint_offsets_rad"):
        set_offsets(loop.state, loop.robot, loop.joint_bus, [0.0, np.nan, 0.0])
