"""The drone's pose drawn in the scene while a pose input is live, outside a hold: the
world frame where the input's latest pose puts it, the drone's label saying fresh or
stale, nothing once the input is lost (app/scene/world_view.py)."""

from __future__ import annotations

import math

import numpy as np
import viser

from app.scene.world_view import WorldView, live_pose
from kinematics import Pose
from kinematics.pose import quaternion_to_matrix


class _Idle:
    mode = "idle"
    extra: dict = {}


def _input(state: str, pose: Pose) -> dict:
    """A pose input's status (GET /api/mav/pose's fields) whose latest sample is ``pose``."""
    return {
        "state": state,
        "position_m": list(pose.position),
        "quaternion": list(pose.quaternion),
        "source": "simulated",
    }


def test_a_live_pose_input_draws_the_drone_and_the_world_where_it_says():
    tilt = math.radians(8)
    pose = Pose.from_arrays([0.02, -0.01, 1.48], [math.cos(tilt / 2), 0.0, math.sin(tilt / 2), 0])
    mount = Pose.from_arrays([0.0, 0.0, -0.08], [1.0, 0.0, 0.0, 0.0])
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = WorldView(server, mount)
        view.update(_Idle(), None)
        assert not view.drone.visible and not view.world.visible  # no input: nothing drawn
        view.update(_Idle(), _input("ok", pose))
        assert view.drone.visible and view.world.visible
        assert view.drone_label.text == "drone (pose input)"
        world_point = np.array([0.1, 0.2, 1.3])  # a world point lands where the pose puts it
        drawn = quaternion_to_matrix(view.world.wxyz) @ world_point + view.world.position
        np.testing.assert_allclose(drawn, (pose @ mount).apply_inverse(world_point), atol=1e-12)
        view.update(_Idle(), _input("stale", pose))
        assert view.world.visible and view.drone_label.text == "drone (pose STALE)"
        view.update(_Idle(), _input("lost", pose))
        assert not view.drone.visible and not view.world.visible
    finally:
        server.stop()


def test_only_a_live_input_with_a_pose_is_drawn():
    pose = Pose.from_arrays([0, 0, 1.5], [1, 0, 0, 0])
    assert live_pose(_input("ok", pose))[1] == "ok"
    assert live_pose({"state": "ok", "position_m": None, "quaternion": None}) is None
    assert live_pose({"state": "none"}) is None and live_pose(None) is None
