"""The tool tip in the gate and the tick: goals are tips, the checks are on the platform.

Laws: with a tool offset d (turned by phi about z when there is a wrist), the gate's answer
for a tip t is the plain gate's answer for the platform point t - Rz(phi) d, shifted back
by the offset; a controller stepped on a fake bus publishes the tip as its position and the
platform centre beside it, and drives the platform to goal - offset.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.config import load_settings
from app.control import commands
from app.control.commands import CommandContext
from app.control.controller import Controller
from app.control.errors import GoalRejected
from kinematics import Tool
from tests.support.fake_bus import HOME_M, FakeBus

PLAIN = CommandContext.from_settings(load_settings()).gate
DOWN = (0.0, 0.0, -0.05)
TIPS = st.tuples(st.floats(-0.25, 0.25), st.floats(-0.25, 0.25), st.floats(-0.45, 0.0)).map(
    np.array
)
OFFSETS = st.tuples(*[st.floats(-0.06, 0.06)] * 3)


def _tooled(offset, wrist: bool = False):
    limits = {"wrist_min_rad": -math.pi, "wrist_max_rad": math.pi} if wrist else {}
    return dataclasses.replace(PLAIN, tool=Tool(offset_m=offset, wrist=wrist), **limits)


def _rz(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _outcome(call):
    try:
        return call()
    except GoalRejected as exc:
        return exc


@settings(max_examples=20, deadline=None)
@given(tip=TIPS, offset=OFFSETS, phi=st.floats(-math.pi, math.pi))
def test_the_gate_judges_a_tip_by_its_platform_point(tip, offset, phi):
    gate = _tooled(offset, wrist=True)
    shift = _rz(phi) @ np.asarray(offset)
    platform = tip - shift
    np.testing.assert_allclose(gate.platform(tip, phi), platform, atol=1e-15)
    assert gate.inside(tip, phi) == PLAIN.inside(platform)
    np.testing.assert_allclose(gate.nearest(tip, phi), PLAIN.nearest(platform) + shift, atol=1e-12)
    np.testing.assert_allclose(
        gate.clamp_point(tip, phi), PLAIN.clamp_point(platform) + shift, atol=1e-12
    )
    near = PLAIN.robot.ik(HOME_M).joints
    tooled = _outcome(lambda: gate.solve(gate.check_point(tip, phi), near, phi))
    plain = _outcome(lambda: PLAIN.solve(PLAIN.check_point(platform), near))
    if isinstance(plain, GoalRejected):
        assert isinstance(tooled, GoalRejected)
        if plain.nearest is not None:
            np.testing.assert_allclose(tooled.nearest, plain.nearest + shift, atol=1e-12)
    else:
        np.testing.assert_allclose(tooled, plain, rtol=0, atol=1e-12)  # to rounding


@settings(max_examples=15, deadline=None)
@given(step=st.tuples(*[st.floats(-0.5, 0.5)] * 3).map(np.array), offset=OFFSETS)
def test_a_jog_clamp_of_the_tip_is_the_platform_clamp_shifted(step, offset):
    gate = _tooled(offset)
    start = HOME_M + np.asarray(offset)  # the tip with the platform at home
    near = PLAIN.robot.ik(HOME_M).joints
    clamped = gate.clamp_towards(start, start + step, near)
    expected = PLAIN.clamp_towards(HOME_M, HOME_M + step, near) + np.asarray(offset)
    # as near the target as the plain clamp; at a tie (a target on a plane of symmetry, two
    # nearest points) either one, so the distances are compared, and the point is accepted
    target = start + step
    assert np.linalg.norm(clamped - target) == pytest.approx(
        np.linalg.norm(expected - target), abs=1e-9
    )
    assert gate.inside(clamped)


def test_a_tip_inside_the_platform_workspace_is_refused_when_its_platform_is_not():
    """The tip [0, 0, -0.09] is a good platform goal, but a 5 cm tool pointing down puts
    the platform at z = -0.04, above the ceiling (-0.06): refused, with a tip that passes."""
    tip = np.array([0.0, 0.0, -0.09])
    PLAIN.solve(PLAIN.check_point(tip), PLAIN.robot.ik(HOME_M).joints)  # passes plain
    gate = _tooled(DOWN)
    with pytest.raises(GoalRejected, match=r"position_m: outside the workspace") as info:
        gate.check_point(tip)
    assert "platform centre would be at [0.0, 0.0, -40.0] mm" in str(info.value)
    assert gate.inside(info.value.nearest)
    assert info.value.nearest[2] <= PLAIN.z_max_m + DOWN[2] + 1e-12


@pytest.mark.parametrize(
    ("phi", "reason"),
    [(0.3, "no wrist axis"), (math.nan, "finite"), (math.inf, "finite"), ("x", "a number")],
)
def test_phi_is_refused_without_a_wrist_naming_phi_rad(phi, reason):
    gate = _tooled(DOWN)
    with pytest.raises(GoalRejected, match="phi_rad") as info:
        gate.check_point(HOME_M, phi)
    assert reason in str(info.value)
    assert _tooled(DOWN, wrist=True).check_phi(0.3) == 0.3 and gate.check_phi(0) == 0.0


class FakeClock:
    now = 1000.0

    def __call__(self) -> float:
        return self.now


def _loop(offset) -> tuple[Controller, FakeClock]:
    clock, bus = FakeClock(), FakeBus()
    loop = Controller(load_settings(tool={"offset_m": offset}), bus, "fake", clock=clock)
    loop.step()
    commands.torque_to(loop.state, loop.ctx, bus, True)
    loop.step()
    return loop, clock


def test_the_loop_publishes_the_tip_and_the_platform_and_drives_the_platform_below_the_goal():
    loop, clock = _loop(DOWN)
    snap = loop.snapshot()
    np.testing.assert_allclose(snap.platform_measured_m, HOME_M, atol=1e-9)
    np.testing.assert_allclose(snap.point_measured_m, snap.platform_measured_m + DOWN)
    np.testing.assert_allclose(snap.goal_m, snap.point_measured_m)  # torque on holds the tip
    assert snap.phi_rad == 0.0
    tip = np.array([0.02, -0.01, -0.30])
    commands.jog_to(loop.state, loop.ctx, loop.gate.check_point(tip))
    for _ in range(400):  # 2 s of ticks: a 6 cm jog at the default limits takes ~0.3 s
        clock.now += loop.period_s
        loop.step()
    snap = loop.snapshot()
    np.testing.assert_allclose(snap.goal_m, tip)
    np.testing.assert_allclose(snap.point_commanded_m, tip, atol=1e-9)
    platform = loop.robot.fk(snap.joints_commanded_rad).points
    np.testing.assert_allclose(platform, tip - DOWN, atol=1e-9)
    np.testing.assert_allclose(snap.platform_measured_m, tip - DOWN, atol=1e-6)


def test_without_a_tool_the_tip_is_the_platform():
    loop, _ = _loop((0.0, 0.0, 0.0))
    snap = loop.snapshot()
    np.testing.assert_array_equal(snap.point_measured_m, snap.platform_measured_m)
    assert loop.gate.tool == Tool()
