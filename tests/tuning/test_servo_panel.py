"""The servo panel's step without a robot: the joint step as a timed path (its tips give
the joints back through IK, it climbs within the loop's joint speed limit and passes the
gate's batch check, a step beyond a joint limit does not), and the step figures of known
responses (a first-order lag, an underdamped second order, one that did not follow); a step
planned only from a fresh rest."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from app.config import load_settings
from app.control.errors import GoalRejected, MotionRefused
from app.control.gate import Gate
from app.runs.feasibility import check_path
from app.runs.paths import JointStepParams
from app.runs.trajectories import plan_sinusoid
from app.tuning.servo_panel import RAD_PER_TICK, plan_joint_step, step_figures
from kinematics import THESIS_DELTA

PERIOD_S = 0.005
SPEED = 7.5  # the default joint speed limit [rad/s]
HOME = np.array([0.0, 0.0, -0.24])


def _gate() -> Gate:
    joints = load_settings().hardware.joints
    return Gate(
        THESIS_DELTA,
        tuple(j.min_angle_rad for j in joints),
        tuple(j.max_angle_rad for j in joints),
        0.002,
        -0.06,
        0.02,
        SPEED * PERIOD_S,
    )


def _step(joint: int, step_rad: float, start=None) -> JointStepParams:
    start = THESIS_DELTA.ik(HOME).joints if start is None else np.asarray(start)
    return JointStepParams(
        joint=joint,
        start_rad=tuple(start.tolist()),
        step_rad=step_rad,
        ramp_rad_s=0.9 * SPEED,
        tip_of=lambda q: THESIS_DELTA.fk(q).points,
    )


def test_a_joint_steps_alone_and_its_tips_give_its_joints_back():
    params = _step(2, math.radians(5.0))
    start = np.array(params.start_rad)
    t = np.arange(0.0, params.duration_s, PERIOD_S)
    joints = params.joints_at(t)
    assert joints[t < params.step_at_s] == pytest.approx(np.tile(start, (int(0.2 / PERIOD_S), 1)))
    assert joints[-1] == pytest.approx(start + [0.0, math.radians(5.0), 0.0])
    assert joints[:, [0, 2]] == pytest.approx(np.tile(start[[0, 2]], (len(t), 1)))
    back, ok = THESIS_DELTA.ik(params.derivatives(t, 0), near=start)
    assert ok.all()
    np.testing.assert_allclose(back, joints, atol=1e-9)
    # it climbs at the ramp's speed, under the loop's limit: no tick is cut short
    assert np.abs(np.diff(joints, axis=0)).max() <= 0.9 * SPEED * PERIOD_S + 1e-12
    # at rest at both ends, where the planner joins it
    for at in (0.0, params.duration_s):
        assert params.derivatives(np.array(at), 1) == pytest.approx(np.zeros(3), abs=1e-12)


def test_a_step_plans_from_where_it_rests_and_passes_the_gates_check():
    params = _step(1, -math.radians(4.0))
    start_m = THESIS_DELTA.fk(np.array(params.start_rad)).points
    plan = plan_sinusoid(params, start_m)
    assert plan.approach_s == pytest.approx(0.0, abs=1e-6)  # it starts where the arm is
    times, points = plan.sample(PERIOD_S)
    check_path(_gate(), times, points, np.array(params.start_rad))


def test_a_step_past_a_joint_limit_fails_the_gates_check():
    gate = _gate()
    start = np.array([gate.joint_max_rad[0] - math.radians(2.0), 0.5, 0.5])
    params = _step(1, math.radians(4.0), start)
    plan = plan_sinusoid(params, THESIS_DELTA.fk(start).points)
    times, points = plan.sample(PERIOD_S)
    with pytest.raises(GoalRejected, match="a joint leaves its limits"):
        check_path(gate, times, points, start)


def _record(response, step_rad: float = 0.05, n: int = 200, before: int = 40):
    """Samples at the loop period: the goal steps at t = 0, the measured angle is
    ``step_rad`` times ``response(t)`` (0 before), from a start of 0.5 rad."""
    t = (np.arange(n) - before) * PERIOD_S
    goal = 0.5 + np.where(t >= 0.0, step_rad, 0.0)
    measured = 0.5 + step_rad * np.where(t >= 0.0, response(np.maximum(t, 0.0)), 0.0)
    return t, goal, measured


def test_a_first_order_lag_has_its_textbook_figures():
    tau = 0.02
    t, goal, measured = _record(lambda t: 1.0 - np.exp(-t / tau))
    figures = step_figures(t, goal, measured)
    assert figures["rise_time_s"] == pytest.approx(tau * math.log(9.0), abs=PERIOD_S / 4)
    assert figures["delay_s"] == pytest.approx(tau * math.log(1 / 0.9), abs=PERIOD_S / 4)
    assert figures["overshoot_pct"] == pytest.approx(0.0, abs=1e-9)
    # within 5 % from t = tau ln 20, seen at the next sample
    assert tau * math.log(20.0) <= figures["settling_s"] <= tau * math.log(20.0) + PERIOD_S
    assert figures["settle_band_rad"] == pytest.approx(0.05 * 0.05, rel=1e-3)
    assert figures["moved_fraction"] == pytest.approx(1.0, abs=1e-3)
    assert figures["steady_error_rad"] == pytest.approx(0.0, abs=1e-4)


def test_an_underdamped_step_shows_its_overshoot_and_a_sag_is_an_error_not_a_miss():
    zeta, wn, sag = 0.5, 60.0, 0.8  # it reaches 80 % of the goal (gravity's sag)
    wd = wn * math.sqrt(1 - zeta**2)
    phase = math.acos(zeta)

    def response(t):
        envelope = np.exp(-zeta * wn * t) / math.sqrt(1 - zeta**2)
        return sag * (1.0 - envelope * np.sin(wd * t + phase))

    t, goal, measured = _record(response)
    figures = step_figures(t, goal, measured)
    expected = 100.0 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))  # 16.3 %
    assert figures["overshoot_pct"] == pytest.approx(expected, abs=0.5)
    assert figures["moved_fraction"] == pytest.approx(sag, abs=1e-3)
    assert figures["steady_error_rad"] == pytest.approx(0.05 * (1 - sag), abs=1e-4)
    assert figures["settling_s"] is not None and figures["settling_s"] > figures["rise_time_s"]


def test_a_joint_that_did_not_follow_has_no_rise_and_says_so():
    t, goal, measured = _record(lambda t: np.full_like(t, 0.1 * RAD_PER_TICK / 0.05))
    figures = step_figures(t, goal, measured)
    assert figures["rise_time_s"] is None and figures["overshoot_pct"] is None
    assert figures["moved_fraction"] == pytest.approx(0.0, abs=0.01)
    assert figures["steady_error_rad"] == pytest.approx(0.05, abs=1e-3)
    empty = step_figures(np.zeros(0), np.zeros(0), np.zeros(0))
    assert set(empty.values()) == {None}


class StandIn:
    """What plan_joint_step reads of a controller: its snapshot, servo ids, gate, robot and
    settings (no loop, no bus)."""

    def __init__(self, velocity_rad_s=(0.0, 0.0, 0.0), **snap) -> None:
        from app.control.state import Snapshot, unread

        joints = THESIS_DELTA.ik(HOME).joints
        base = {
            "mode": "idle",
            "torque": True,
            "joints_commanded_rad": joints,
            "point_commanded_m": HOME,
            "goal_m": HOME,
            "readings": {**unread(), "velocity_rad_s": np.asarray(velocity_rad_s, float)},
        }
        self.snap = Snapshot(**{**base, **snap})
        self.servo_ids = (11, 12, 13)
        self.gate, self.robot = _gate(), THESIS_DELTA
        self.settings = load_settings()

    def snapshot(self):
        return self.snap


def test_a_step_is_planned_from_the_commanded_joints_of_the_servos_joint():
    params = plan_joint_step(StandIn(), 12, math.radians(2.0), 1.5)
    assert params.joint == 2 and params.duration_s == 1.5
    assert params.start_rad == pytest.approx(THESIS_DELTA.ik(HOME).joints)
    assert params.ramp_rad_s == pytest.approx(0.9 * SPEED)
    np.testing.assert_allclose(params.derivatives(np.array(0.0), 0), HOME, atol=1e-12)
    with pytest.raises(KeyError):
        plan_joint_step(StandIn(), 4, 0.02, 1.0)


@pytest.mark.parametrize(
    ("snap", "words"),
    [
        ({"torque": False}, "torque is off"),
        ({"estopped": True}, "e-stop is active"),
        ({"stale": True, "feedback_age_ms": 300.0}, "stale (no fresh read for 300 ms)"),
        ({"mode": "test"}, "a test is running"),
        ({"mode": "jog", "goal_m": HOME + [0.0, 0.0, 0.01]}, "on its way to its goal"),
        ({"velocity_rad_s": np.array([0.0, 0.0, 0.2])}, "moving (joint 3 at 11.5 deg/s)"),
        ({"joints_commanded_rad": np.full(3, np.nan)}, "no commanded joints"),
    ],
)
def test_a_step_starts_only_from_a_fresh_rest(snap, words):
    with pytest.raises(MotionRefused, match=re.escape(words)):
        plan_joint_step(StandIn(**snap), 12, 0.02, 1.0)


def test_a_few_stale_ticks_are_no_reason_to_refuse():
    plan_joint_step(StandIn(stale=True, feedback_age_ms=40.0), 12, 0.02, 1.0)


@pytest.mark.parametrize("step_deg", [0.2, -0.3, 5.5, -6.0])
def test_a_step_out_of_its_range_names_step_rad(step_deg):
    with pytest.raises(GoalRejected, match=r"^step_rad: .* 0\.5 to 5 deg either way"):
        plan_joint_step(StandIn(), 12, math.radians(step_deg), 1.0)
