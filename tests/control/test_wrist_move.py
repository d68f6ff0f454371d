"""A move with a wrist: phi is the path's fourth axis, planned with the three others.

Laws, on an unstarted loop over a fake four-servo bus stepped tick by tick: a move that
changes both the tip and phi ends both on the same tick, the wrist's goals never step
faster than its speed limit, and the tip reached (the legs' platform point plus the tool
offset turned by the written phi) is the goal; without a wrist a move is as before.
"""

from __future__ import annotations

from concurrent.futures import Future

import numpy as np
import pytest

from app.config import load_settings
from app.control import commands
from app.control.controller import Controller
from app.control.sources import MoveSource
from tests.support.fake_bus import HOME_M, HOME_RAD, FakeBus

WRIST = {"enabled": True, "min_angle_rad": -1.0, "max_angle_rad": 2.0, "max_speed_rad_s": 2.0}
TOOL = {"offset_m": [0.03, 0.0, -0.02]}  # off the axis: the legs' goals depend on phi
SETTINGS = load_settings(wrist=WRIST, tool=TOOL)
STEP_RAD = 2.0 / SETTINGS.loop.rate_hz  # the wrist's speed limit per tick
MAX_TICKS = 2000


def _loop(phi0: float = 0.3) -> tuple[Controller, FakeBus]:
    fake = FakeBus(errors=((), (), (), ()))
    fake.position = np.array([*HOME_RAD, phi0])
    control = Controller(SETTINGS, fake, "fake")  # type: ignore[arg-type]
    control.step()
    commands.torque_to(control.state, control.ctx, control.servos, True)
    return control, fake


def _run(control: Controller, fake: FakeBus) -> np.ndarray:
    """Step until the move has ended and settled; the goals written meanwhile (n, 4)."""
    start = len(fake.calls)
    for _ in range(MAX_TICKS):
        control.step()
        if control.state.source is None and control.state.settle_rad is None:
            break
    else:
        pytest.fail(f"the move did not end in {MAX_TICKS} ticks")
    goals = [call[1] for call in fake.calls[start:] if call[0] == "write_goal"]
    return np.array(goals)


def _tips(control: Controller, goals: np.ndarray) -> np.ndarray:
    """The tip each write commands: the legs' platform point and the tool at its phi."""
    robot, gate = control.robot, control.gate
    return np.array([gate.tip(robot.fk(g[:3]).points, g[3]) for g in goals])


def _last_change(values: np.ndarray, tol: float) -> int:
    """Index of the last row that differs from the final one by more than ``tol``."""
    off = np.flatnonzero(np.abs(values - values[-1]).reshape(len(values), -1).max(axis=1) > tol)
    return int(off[-1]) if off.size else -1


@pytest.mark.parametrize(
    ("delta_m", "phi"),
    [
        ((0.01, 0.0, 0.0), 1.8),  # the wrist's turn is the long one: the tip waits for it
        ((0.0, -0.06, 0.03), 0.5),  # the tip's path is the long one: the wrist waits
    ],
)
def test_a_move_brings_the_tip_and_phi_in_together_within_the_wrist_speed(delta_m, phi) -> None:
    control, fake = _loop(phi0=0.3)
    start_tip = control.state.point_m.copy()
    target = start_tip + np.array(delta_m)
    goal, _ = commands.check_move(control.gate, target, None, False, HOME_RAD, phi)
    done = commands.move(control.state, control.ctx, goal, None, False, phi)
    assert isinstance(control.state.source, MoveSource) and control.state.source.wrist
    goals = _run(control, fake)
    tips = _tips(control, goals)
    # both arrive, the tip at the goal through the legs and the wrist's written angle
    np.testing.assert_allclose(tips[-1], target, atol=1e-9)
    assert goals[-1, 3] == pytest.approx(phi, abs=1e-12)
    # ... on the same tick: neither is still moving once the other has stopped
    tip_end, phi_end = _last_change(tips, 1e-7), _last_change(goals[:, 3], 1e-9)
    assert abs(tip_end - phi_end) <= 1, (tip_end, phi_end, len(goals))
    # and set off together (no turn first, then a move)
    assert np.linalg.norm(tips[1] - start_tip) > 0 and goals[1, 3] != 0.3
    # the wrist never beyond its speed limit, and the move no shorter than its turn needs
    assert np.abs(np.diff(goals[:, 3])).max() <= STEP_RAD * (1 + 1e-9)
    assert done["duration_s"] >= abs(phi - 0.3) / 2.0
    snap = control.snapshot()
    assert snap.phi_goal_rad == snap.phi_commanded_rad == pytest.approx(phi, abs=1e-12)
    assert not snap.faults and snap.warning is None


def test_a_joint_space_move_turns_the_wrist_with_the_legs() -> None:
    control, fake = _loop(phi0=0.0)
    target = np.asarray(HOME_RAD) + np.array([0.15, -0.1, 0.05])
    commands.move(control.state, control.ctx, target, None, True, -0.8)
    goals = _run(control, fake)
    np.testing.assert_allclose(goals[-1], [*target, -0.8], atol=1e-9)
    legs_end, phi_end = _last_change(goals[:, :3], 1e-9), _last_change(goals[:, 3], 1e-9)
    assert abs(legs_end - phi_end) <= 1, (legs_end, phi_end)
    assert np.abs(np.diff(goals[:, 3])).max() <= STEP_RAD * (1 + 1e-9)


def test_a_move_turns_the_wrist_from_its_held_goal_or_from_where_torque_on_found_it() -> None:
    control, fake = _loop(phi0=0.3)
    fake.position[3] = 0.1  # pushed with torque on: the servo still holds 0.3
    control.step()
    commands.move(control.state, control.ctx, control.state.point_m.copy(), None, False, 0.0)
    goals = _run(control, fake)
    assert 0.3 - STEP_RAD * (1 + 1e-9) <= goals[0, 3] < 0.3  # from the held goal, no jump
    commands.torque_to(control.state, control.ctx, control.servos, False)
    fake.position[3] = -0.5  # turned by hand with torque off
    control.step()
    commands.torque_to(control.state, control.ctx, control.servos, True)
    control.step()
    commands.move(control.state, control.ctx, control.state.point_m.copy(), None, False, 0.0)
    goals = _run(control, fake)
    assert -0.5 < goals[0, 3] <= -0.5 + STEP_RAD * (1 + 1e-9)  # from where it was found
    assert goals[-1, 3] == pytest.approx(0.0, abs=1e-12)


def test_without_a_wrist_a_move_plans_three_axes_and_leaves_phi_alone() -> None:
    fake = FakeBus()
    control = Controller(load_settings(), fake, "fake")  # type: ignore[arg-type]
    control.step()
    commands.torque_to(control.state, control.ctx, control.servos, True)
    assert control.ctx.wrist_limits is None
    commands.move(control.state, control.ctx, HOME_M + [0.01, 0, 0], None, False)
    source = control.state.source
    assert isinstance(source, MoveSource) and source.wrist is None
    assert source.next(0.005).phi_rad is None
    goals = _run(control, fake)
    assert goals.shape[1] == 3
    np.testing.assert_allclose(control.robot.fk(goals[-1]).points, HOME_M + [0.01, 0, 0], atol=1e-9)


def test_the_goal_shown_is_the_move_s_target_and_a_jog_stops_the_turn_where_it_is() -> None:
    control, fake = _loop(phi0=0.0)
    tip = control.state.point_m.copy()
    commands.move(control.state, control.ctx, tip + [0.0, 0.01, 0.0], None, False, 1.5)
    for _ in range(20):
        control.step()
    snap = control.snapshot()
    assert snap.phi_goal_rad == 1.5  # as goal_m is the move's target, not the path's point
    assert 0.0 < snap.phi_commanded_rad < 1.0
    # a jog replaces the move: the wrist stays where the move had taken it, and the tip's
    # goals are at that angle (not turning on towards 1.5 while the legs assume otherwise)
    commands.jog_by(control.state, control.ctx, np.array([0.001, 0.0, 0.0]))
    start = len(fake.calls)
    for _ in range(200):  # a jog stays the source: well past its 1 mm
        control.step()
    goals = np.array([call[1] for call in fake.calls[start:] if call[0] == "write_goal"])
    turned = control.snapshot().phi_commanded_rad
    assert np.ptp(goals[:, 3]) <= 1e-12 and turned < 1.0
    assert control.state.phi_rad == pytest.approx(turned, abs=1e-12)
    np.testing.assert_allclose(_tips(control, goals)[-1], control.state.goal_m, atol=1e-9)


def test_a_goal_that_turns_the_wrist_keeps_the_tip_on_its_path() -> None:
    """A goal (the page's phi keys, POST /api/goal) that turns the wrist moves the legs with
    it: every write's tip stays on the straight path to the goal (here the tip stays put),
    never the legs at the new angle while the wrist still turns (off by the offset times the
    turn: 18 mm here)."""
    control, fake = _loop(phi0=0.3)
    tip = control.state.point_m.copy()
    phi = control.gate.check_phi(0.8)
    goal = control.gate.check_point(tip, phi)
    commands.jog_to(control.state, control.ctx, goal, phi_rad=phi)
    start = len(fake.calls)
    for _ in range(MAX_TICKS):  # until the wrist is there (a jog source never ends itself)
        control.step()
        if fake.calls[-1][0] == "write_goal" and fake.calls[-1][1][3] == pytest.approx(0.8):
            break
    goals = np.array([call[1] for call in fake.calls[start:] if call[0] == "write_goal"])
    assert len(goals) > 10 and goals[-1, 3] == pytest.approx(0.8, abs=1e-12)
    np.testing.assert_allclose(_tips(control, goals), np.tile(tip, (len(goals), 1)), atol=1e-6)
    assert np.abs(np.diff(goals[:, 3])).max() <= STEP_RAD * (1 + 1e-9)


def test_new_joint_offsets_keep_the_goal_and_the_points_tips() -> None:
    """Applying joint offsets (a calibration's apply) re-reads the loop's points through the
    new offsets: with a tool they stay tool tips at the wrist's angle (an attacker's trial
    saw the goal become the platform centre, 48 mm from the tip, until the next motion)."""
    control, _ = _loop(phi0=-0.4)
    control.step()

    def now(command):  # the control thread's part, run here at once (the loop is stepped)
        future = Future()
        future.set_result(command())
        return future

    control.submit = now  # type: ignore[method-assign]
    goal = control.state.goal_m.copy()
    control.set_joint_offsets(np.zeros(3)).result()
    np.testing.assert_allclose(control.state.goal_m, goal, atol=1e-9)  # nothing changed
    control.set_joint_offsets([0.01, -0.02, 0.015]).result()
    state, robot, gate = control.state, control.robot, control.gate
    np.testing.assert_allclose(state.goal_m, gate.tip(robot.fk(state.commanded_rad).points, -0.4))
    measured = gate.tip(robot.fk(state.joints.position_rad).points, -0.4)
    np.testing.assert_allclose(state.point_m, measured, atol=1e-12)
