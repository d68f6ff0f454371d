"""Check a whole planned path before anything moves: workspace, joints, speed.

The path is sampled at the loop's period and checked in one batch with the same limits the
gate applies per tick, so a run that starts will not be held up half-way by the gate.
A failure names the first offending time, point and reason.
"""

from __future__ import annotations

import numpy as np

from app.control.errors import GoalRejected
from app.control.gate import Gate


def _first(mask: np.ndarray) -> int | None:
    bad = np.flatnonzero(~mask)
    return int(bad[0]) if bad.size else None


def check_path(gate: Gate, times_s: np.ndarray, points_m: np.ndarray, near: np.ndarray) -> None:
    """Raise GoalRejected at the first sample that would fail; return None if all pass.

    Args:
        gate: the controller's gate (limits in force).
        times_s: sample times (N,) [s], evenly spaced by the loop period.
        points_m: the path (N, 3) [m] in the base frame.
        near: current joints (3,), to pick the IK branch the robot is on.
    """
    robot = gate.robot
    checks = [
        ("outside the workspace", robot.reachable(points_m, margin=gate.margin_m)),
        ("above the platform ceiling", points_m[:, 2] <= gate.z_max_m),
    ]
    for reason, mask in checks:
        _raise_at(_first(mask), reason, times_s, points_m)
    joints, ok = _follow_branch(robot, points_m, near)
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


def _follow_branch(robot, points_m: np.ndarray, near: np.ndarray):
    """IK along the path as the loop does it: each sample on the branch nearest the last
    good solution (a single ``near`` for the whole path would jump branches far from the
    start). From a start outside the joint limits (a relaxed, hanging arm) the gate's
    knee-out fallback applies, so the path is followed from the knee-out branch.

    The sample-by-sample rule is a recurrence; it is solved here in batches as a fixed
    point: solve every sample near the previous pass's answer for the sample before it.
    If pass k is exact up to sample d, pass k + 1 is exact up to d + 1, and the first
    sample where two passes differ is where the earlier pass stopped being exact; so each
    pass fixes at least one more sample, and a pass that changes nothing is the answer.
    Paths that stay on one branch (all that pass the workspace margin) take two passes.
    """
    previous = np.asarray(near, dtype=np.float64)
    if not np.isfinite(previous).all():
        previous = robot.ik(points_m[0]).joints
    count = len(points_m)
    joints, ok = robot.ik(points_m, near=np.broadcast_to(previous, (count, 3)))
    joints, ok = np.array(joints, dtype=np.float64), np.array(ok, dtype=bool)
    exact = 0  # samples [0, exact) are known to be what the recurrence gives
    while exact < count:
        references = _last_good_before(joints, ok, previous)[exact:]
        solved, good = robot.ik(points_m[exact:], near=references)
        same = (good == ok[exact:]) & (
            (solved == joints[exact:]) | (np.isnan(solved) & np.isnan(joints[exact:]))
        ).all(axis=-1)
        joints[exact:], ok[exact:] = solved, good
        changed = np.flatnonzero(~same)
        if not changed.size:
            break
        exact += int(changed[0]) + 1
    return joints, ok


def _last_good_before(joints: np.ndarray, ok: np.ndarray, first: np.ndarray) -> np.ndarray:
    """Per sample i: the joints of the last good sample before i, or ``first`` if none."""
    good_index = np.where(ok, np.arange(len(ok)), -1)
    last = np.maximum.accumulate(good_index)
    before = np.concatenate([[-1], last[:-1]])
    return np.vstack([joints, first[None, :]])[before]  # index -1: the row ``first``


def _raise_at(index: int | None, reason: str, times_s: np.ndarray, points_m: np.ndarray) -> None:
    if index is None:
        return
    point = ", ".join(f"{v:.4f}" for v in points_m[index])
    message = f"infeasible: {reason} at t = {times_s[index]:.3f} s, point [{point}] m"
    if index == 0:  # the approach starts where the robot is: that is what fails
        message += "; the robot is there now: move it into the workspace first (a goal or jog)"
    raise GoalRejected(message)
