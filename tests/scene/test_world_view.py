"""Hold-in-world in the scene: the world frame is drawn where the drone's pose puts it."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import viser

from app.scene.world_view import WorldView
from kinematics import Pose
from kinematics.pose import quaternion_to_matrix
from tests.support.wait import WAIT_S, wait_for


class _Snapshot:
    """A snapshot in hold-world mode whose hold works from ``pose``."""

    mode = "hold-world"

    def __init__(self, pose: Pose) -> None:
        self.extra = {"drone_pose": [*pose.position, *pose.quaternion]}


def test_world_frame_maps_world_points_into_the_base_frame():
    yaw = math.radians(30)
    pose = Pose.from_arrays([0.4, -0.2, 1.5], [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    mount = Pose.from_arrays([0.0, 0.0, -0.08], [math.cos(0.1), math.sin(0.1), 0.0, 0.0])
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = WorldView(server, mount)
        view.update(_Snapshot(pose))
        assert view.world.visible and view.drone.visible
        world_point = np.array([0.3, 0.1, 1.2])
        drawn = quaternion_to_matrix(view.world.wxyz) @ world_point + view.world.position
        np.testing.assert_allclose(drawn, (pose @ mount).apply_inverse(world_point), atol=1e-12)
        body_point = np.array([0.01, 0.02, 0.03])
        drawn = quaternion_to_matrix(view.drone.wxyz) @ body_point + view.drone.position
        np.testing.assert_allclose(drawn, mount.apply_inverse(body_point), atol=1e-12)
        view.update(None)  # another mode: the frames go away
        assert not view.world.visible and not view.drone.visible
    finally:
        server.stop()


@pytest.mark.slow
def test_hold_mode_shows_the_frames(scene, app_client):
    response = app_client.post("/api/hold", json={"frame": "current", "source": "simulated"})
    assert response.status_code == 200, response.text
    try:
        wait_for(lambda: scene.controller.snapshot().mode == "hold-world", "hold-world mode")
        scene.update(time.monotonic())
        assert scene.world.world.visible and scene.world.drone.visible
    finally:
        scene.controller.reset().result(timeout=WAIT_S)
    scene.update(time.monotonic())
    assert not scene.world.world.visible
