"""The run planner's batch paths equal the sample-by-sample rules they replace, and a run
longer than the configured bound is refused before it is sampled (planning time bounded)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.control.errors import GoalRejected
from app.runs.feasibility import _follow_branch
from app.runs.paths import ChirpParams, StepParams, WaypointParams
from app.runs.trajectories import SinusoidParams, plan_sinusoid
from kinematics import THESIS_DELTA
from tests.support.planning import resting_manager

START = np.array([0.0, 0.0, -0.24])


def follow_one_by_one(robot, points_m, near):
    """The rule as the loop applies it: each sample near the last good solution."""
    joints, ok = np.empty_like(points_m), np.empty(len(points_m), dtype=bool)
    previous = np.asarray(near, dtype=np.float64)
    if not np.isfinite(previous).all():
        previous = robot.ik(points_m[0]).joints
    for index, point in enumerate(points_m):
        joints[index], ok[index] = robot.ik(point, near=previous)
        if ok[index]:
            previous = joints[index]
    return joints, ok


@st.composite
def walks(draw) -> np.ndarray:
    """Random walks from near the centre, some wandering out of reach and back, some to
    the workspace's edge where the knee-in root is the nearer one."""
    count = draw(st.integers(1, 60))
    step = draw(st.sampled_from([0.001, 0.01, 0.05, 0.2]))
    seed = draw(st.integers(0, 2**32 - 1))
    steps = np.random.default_rng(seed).normal(0.0, step, (count, 3))
    steps[0] = 0.0  # from the start point, reachable: where a checked path begins
    return START + np.cumsum(steps, axis=0)


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(walks(), st.sampled_from(["start", "nan", "knee_in"]))
def test_batch_branch_following_equals_the_sample_by_sample_rule(points, near_kind):
    near = {
        "start": THESIS_DELTA.ik(START).joints,
        "nan": np.full(3, np.nan),
        "knee_in": np.array([-1.5, 2.0, -0.8]),  # far from knee-out: branches switch
    }[near_kind]
    joints, ok = _follow_branch(THESIS_DELTA, points, near)
    expected, expected_ok = follow_one_by_one(THESIS_DELTA, points, near)
    np.testing.assert_array_equal(ok, expected_ok)
    np.testing.assert_allclose(joints[ok], expected[ok], rtol=0, atol=1e-12)


PATHS = [
    SinusoidParams(duration_s=1.0),
    ChirpParams(duration_s=1.0, f0_hz=3.0, f1_hz=0.5),
    StepParams(step_at_s=0.3, duration_s=0.6),
    WaypointParams(((0, 0, -0.24), (0.02, 0, -0.25), (0.02, 0.02, -0.22)), (0, 0.4, 0.9)),
]


@pytest.mark.parametrize("params", PATHS, ids=lambda p: type(p).__name__)
def test_batch_sampling_equals_point_at(params):
    plan = plan_sinusoid(params, START + [0.01, -0.01, 0.0])
    times, points = plan.sample(0.005)
    assert len(times) == plan.samples(0.005)
    expected = np.array([plan.point_at(t) for t in times])
    np.testing.assert_allclose(points, expected, rtol=0, atol=1e-12)


def test_a_run_longer_than_max_samples_is_refused_naming_the_limit(tmp_path):
    runs = resting_manager(tmp_path, START, max_samples=2000)  # 10 s at 200 Hz
    runs.plan(SinusoidParams(amplitude_m=(0.01, 0.01, 0.01), duration_s=5.0))
    with pytest.raises(GoalRejected, match="runs.max_samples = 2000"):
        runs.plan(SinusoidParams(amplitude_m=(0.01, 0.01, 0.01), duration_s=12.0))
