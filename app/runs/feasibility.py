"""Check a whole planned path before anything moves: workspace, joints, speed.

The path is sampled at the loop's period and checked in one batch with the same limits the
gate applies per tick, so a run that starts will not be held up half-way by the gate.
A failure names the first offending time, point and reason.
"""

from __future__ import annotations

import numpy as np

from app.control.branch import follow_branch as _follow_branch
from app.control.errors import GoalRejected
from app.control.gate import Gate


def _first(mask: np.ndarray) -> int | None:
    bad = np.flatnonzero(~mask)
    return int(bad[0]) if bad.size else None


def check_path(
    gate: Gate,
    times_s: np.ndarray,
    points_m: np.ndarray,
    near: np.ndarray,
    phi_rad: np.ndarray | None = None,
) -> None:
    """Raise GoalRejected at the first sample that would fail; return None if all pass.

    Args:
        gate: the controller's gate (limits in force).
        times_s: sample times (N,) [s], evenly spaced by the loop period.
        points_m: the path (N, 3) [m] in the base frame, of the tool tip (at ``phi_rad``); the
            checks apply to the platform centre each implies (``gate.platform``) and the
            failures name the tip.
        near: current joints (3,), to pick the IK branch the robot is on.
        phi_rad: the wrist angle (N,) [rad] at each sample (None: 0, no wrist turning).
    """
    robot = gate.robot
    phi = 0.0 if phi_rad is None else np.asarray(phi_rad, dtype=np.float64)
    platform = gate.platform(points_m, phi)
    checks = [
        ("outside the workspace", robot.reachable(platform, margin=gate.margin_m)),
        ("above the platform ceiling", platform[:, 2] <= gate.z_max_m),
    ]
    for reason, mask in checks:
        _raise_at(_first(mask), reason, times_s, points_m)
    joints, ok = _follow_branch(robot, platform, near)
    _raise_at(_first(ok), "no joint solution", times_s, points_m)
    low, high = np.asarray(gate.joint_min_rad), np.asarray(gate.joint_max_rad)
    _raise_at(
        _first(((joints >= low) & (joints <= high)).all(axis=-1)),
        "a joint leaves its limits",
        times_s,
        points_m,
    )
    dexterity = robot.dexterity(joints)
    _raise_at(
        _first(dexterity >= gate.min_dexterity), "too close to a singularity", times_s, points_m
    )
    # sampled at the loop period, so a sample-to-sample step is what one tick would ask
    step = np.abs(np.diff(joints, axis=0)).max(axis=-1)
    index = _first(np.concatenate([[True], step <= gate.max_step_rad + 1e-12]))
    if index is not None:
        dt = float(times_s[1] - times_s[0])
        speed = step[index - 1] / dt
        _raise_at(index, f"joint speed {speed:.2f} rad/s above the limit", times_s, points_m)


def _raise_at(index: int | None, reason: str, times_s: np.ndarray, points_m: np.ndarray) -> None:
    if index is None:
        return
    point = ", ".join(f"{v:.4f}" for v in points_m[index])
    message = f"infeasible: {reason} at t = {times_s[index]:.3f} s, point [{point}] m"
    if index == 0:  # the approach starts where the robot is: that is what fails
        message += "; the robot is there now: move it into the workspace first (a goal or jog)"
    raise GoalRejected(message)
