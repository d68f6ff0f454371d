"""The IK branch the control loop follows along a path, solved for a whole path at once.

Used by the run check (app/runs/feasibility.py) and the program check
(app/programs/verify.py): both must see the joints the loop would command.
"""

from __future__ import annotations

import numpy as np


def follow_branch(robot, points_m: np.ndarray, near: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """IK along the path as the loop does it: (joints (N, 3) [rad], ok (N,)) for
    ``points_m`` (N, 3) [m] from joints ``near`` (3,) [rad]. Each sample is on the branch
    nearest the last good solution (a single ``near`` for the whole path would jump
    branches far from the start). From a start outside the joint limits (a relaxed,
    hanging arm) the gate's knee-out fallback applies, so the path is followed from the
    knee-out branch.

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
