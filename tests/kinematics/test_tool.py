"""The tool point (kinematics/tool.py): offset and wrist, against hand-computed cases."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinematics import DeltaError, Tool
from tests.support.strategies import robot_and_joints


def test_tool_offset_and_wrist():
    tool = Tool(offset_m=(0.02, 0.0, -0.05), wrist=True)
    platform = np.array([0.0, 0.0, -0.24])
    np.testing.assert_allclose(tool.tip(platform), [0.02, 0.0, -0.29])
    np.testing.assert_allclose(tool.tip(platform, phi=math.pi / 2), [0.0, 0.02, -0.29], atol=1e-15)
    tips = tool.tip(np.tile(platform, (2, 1)), phi=[0.3, -1.0])
    np.testing.assert_allclose(tool.platform(tips, phi=[0.3, -1.0]), np.tile(platform, (2, 1)))
    assert tool.length_m == pytest.approx(math.hypot(0.02, 0.05))


def test_tool_without_wrist_refuses_phi_and_bad_offsets():
    with pytest.raises(DeltaError, match="wrist"):
        Tool(offset_m=(0.0, 0.0, -0.05)).tip([0.0, 0.0, -0.2], phi=0.5)
    with pytest.raises(ValueError, match="offset_m"):
        Tool(offset_m=(0.0, math.nan, 0.0))


OFFSETS = st.tuples(*[st.floats(-0.2, 0.2)] * 3)
ANGLES = st.floats(-4 * math.pi, 4 * math.pi)


def _rz(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("kind", ["rotary", "linear"])
@settings(max_examples=40, deadline=None)
@given(data=st.data(), offset=OFFSETS, phi=ANGLES)
def test_tip_is_the_fk_platform_plus_the_rotated_offset(kind, data, offset, phi):
    """Law (paper section 2, theta_4 about the platform's z): tip = FK(q) + Rz(phi) offset,
    and the platform that puts the tip there is FK(q) again, whose IK gives q back."""
    robot, joints = data.draw(robot_and_joints(kind, shape=(4,)))
    platform, ok = robot.fk(joints)
    platform, joints = platform[ok], joints[ok]
    tool = Tool(offset_m=offset, wrist=True)
    tips = tool.tip(platform, phi)
    np.testing.assert_allclose(tips, platform + _rz(phi) @ np.asarray(offset), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(tips - platform, axis=-1), tool.length_m, atol=1e-12)
    back = tool.platform(tips, phi)
    np.testing.assert_allclose(back, platform, atol=1e-12)
    if len(back):
        solved, solved_ok = robot.ik(back, near=joints)
        assert solved_ok.all()
        np.testing.assert_allclose(robot.fk(solved).points, platform, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(offset=OFFSETS, phi=ANGLES, turn=ANGLES)
def test_the_wrist_turns_only_the_horizontal_part_of_the_offset(offset, phi, turn):
    """Law: turning by phi then by turn is turning by phi + turn; z never changes; a zero
    offset is the platform centre at any phi."""
    tool = Tool(offset_m=offset, wrist=True)
    platform = np.array([0.01, -0.02, -0.25])
    once = tool.tip(platform, phi + turn) - platform
    np.testing.assert_allclose(once, _rz(turn) @ (tool.tip(platform, phi) - platform), atol=1e-12)
    assert once[2] == pytest.approx(offset[2])
    np.testing.assert_array_equal(Tool(wrist=True).tip(platform, phi), platform)
    # a Python float (the control tick's fast path) and an array agree
    np.testing.assert_allclose(tool.tip(platform, phi), tool.tip(platform, np.array(phi)))


def test_without_a_wrist_phi_zero_is_the_plain_offset_in_any_batch():
    tool = Tool(offset_m=(0.0, 0.01, -0.05))
    points = np.zeros((2, 3, 3))
    np.testing.assert_array_equal(tool.tip(points, np.zeros((2, 3))), points + [0.0, 0.01, -0.05])
    np.testing.assert_array_equal(tool.platform(tool.tip(points)), points)
