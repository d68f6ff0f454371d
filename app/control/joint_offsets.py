"""Joint offsets found by calibration, applied between the bus and the loop.

A calibration finds o_i, the mechanism's angle minus the angle the joint reports
(docs/calibration.md). Until the config's zero offsets are rewritten and the server
restarted, the loop applies them itself: it reads q + o and writes (goal - o), which is
what new zero offsets of ``zero - direction * o / RAD_PER_TICK`` ticks would do (without
the tick's rounding). ``OffsetBus`` wraps the bus for everything in the loop that reads
joint positions or writes goals; every other call goes to the bus unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from app.control.errors import MotionRefused
from app.control.loop_state import LoopState
from app.control.sources import JogSource
from hardware.bus import JointState, ServoBus


class OffsetBus:
    """``bus`` with ``offsets_rad`` (3,) added to read positions and taken off goals."""

    def __init__(self, bus: ServoBus) -> None:
        self.inner = bus
        self.offsets_rad = np.zeros(3)

    def read_state(self) -> JointState:
        state = self.inner.read_state()
        if not self.offsets_rad.any():
            return state
        return replace(state, position_rad=np.asarray(state.position_rad) + self.offsets_rad)

    def write_goal(self, positions_rad: Any) -> None:
        if not self.offsets_rad.any():  # none applied: the goal goes as it is
            self.inner.write_goal(positions_rad)
            return
        self.inner.write_goal(np.asarray(positions_rad, dtype=np.float64) - self.offsets_rad)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def set_offsets(
    state: LoopState,
    robot: Any,
    bus: OffsetBus,
    offsets_rad: Any,
    tip_measured: Callable[[np.ndarray], np.ndarray] = lambda platform: platform,
    tip_commanded: Callable[[np.ndarray], np.ndarray] = lambda platform: platform,
) -> list[float]:
    """Use ``offsets_rad`` (3,) [rad] from now on (control thread), holding the arm where it
    is: what the loop read and commanded is shifted by the change, so the goal written to
    the servos stays the same ticks. Refused while a motion runs or the arm still settles
    onto a move's goal (MotionRefused); a jog that has arrived at its goal (not held) only
    holds it, so it ends here and the servos hold the same goal.
    ``tip_measured`` / ``tip_commanded``: the tool tip [m] of a platform point (3,) at the
    measured / commanded wrist angle (the platform itself without a tool): the loop's points
    and goal are tips.

    Returns the offsets now in use [rad].
    """
    new = np.asarray(offsets_rad, dtype=np.float64)
    if new.shape != (3,) or not np.isfinite(new).all():
        raise ValueError(f"joint_offsets_rad: expected 3 finite numbers, got {offsets_rad!r}")
    arrived = (
        isinstance(state.source, JogSource)
        and state.source.at_rest
        and state.hold_velocity_m_s is None  # a held jog's next heartbeat moves it again
    )
    if state.source is not None and not arrived:
        raise MotionRefused(
            f"a {state.source.name} is running: joint offsets change only while the arm rests"
        )
    if state.settle_rad is not None:  # a finished move's last steps, at the speed limit
        raise MotionRefused(
            "the arm is still settling onto its last goal: joint offsets change only while "
            "the arm rests"
        )
    if arrived:  # a jog at its goal only holds it: it ends, the servos hold the same goal
        state.source = None
    delta = new - bus.offsets_rad
    bus.offsets_rad = new
    if state.joints is not None:
        state.joints = replace(state.joints, position_rad=state.joints.position_rad + delta)
        state.platform_m = robot.fk(state.joints.position_rad).points
        state.point_m = tip_measured(state.platform_m)
    if state.commanded_rad is not None:
        state.commanded_rad = state.commanded_rad + delta
        state.commanded_point_m = tip_commanded(robot.fk(state.commanded_rad).points)
        if state.torque:
            state.goal_m = state.commanded_point_m.copy()
    state.resync = True  # the next motion starts from what is measured now
    state.notice = "joint offsets now " + ", ".join(f"{math.degrees(v):+.3f}" for v in new) + " deg"
    return new.tolist()
