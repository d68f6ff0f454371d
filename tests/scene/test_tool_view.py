"""The tool in the scene: a segment from the platform centre to the tip, and the volume
where the tip may go (the platform's moved by the offset)."""

from __future__ import annotations

import numpy as np
import pytest
import viser

from app.scene.robot_view import RobotView
from app.scene.workspace_view import WorkspaceView
from kinematics import THESIS_DELTA, Tool

OFFSET = (0.01, 0.0, -0.05)


@pytest.mark.slow
def test_the_tool_is_drawn_from_the_platform_centre_to_the_tip():
    joints = THESIS_DELTA.ik([0.02, -0.01, -0.22]).joints
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = RobotView(server, THESIS_DELTA, "/tooled", tool=Tool(offset_m=OFFSET))
        plain = RobotView(server, THESIS_DELTA, "/plain", tool=Tool())
        assert view.update(joints) and plain.update(joints)
        assert plain.tool is None  # no offset, nothing to draw
        segment = np.asarray(view.tool.points)[0]
        np.testing.assert_allclose(segment[0], view.platform.position, atol=1e-6)
        np.testing.assert_allclose(segment[1] - segment[0], OFFSET, atol=1e-6)
        view.visible = False
        assert not view.tool.visible
        workspace = WorkspaceView(
            server, THESIS_DELTA, margin_m=0.002, z_max_m=-0.06, tool_offset_m=OFFSET
        )
        np.testing.assert_allclose(workspace.volume.position, OFFSET)
        for handle in (view, plain, workspace):
            handle.remove()
    finally:
        server.stop()
