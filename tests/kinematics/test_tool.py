"""The tool point (kinematics/tool.py): offset and wrist, against hand-computed cases."""

import math

import numpy as np
import pytest

from kinematics import DeltaError, Tool


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
