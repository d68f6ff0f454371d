"""Hold-in-world in the scene: the world frame, the drone's frame and the world-fixed goal.

The scene is drawn in the base frame, so while the drone drifts the world frame (and the
goal fixed in it) move and the robot stays put, which is what the servos see. Shown only
while the loop holds in the world (mode ``hold-world``, app/world/hold.py).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import viser

from kinematics import Pose

HOLD_MODE = "hold-world"


def drone_pose(snap: Any) -> Pose | None:
    """The drone's body-to-world pose a hold works from, as the loop's snapshot ``snap``
    carries it (``extra["drone_pose"]``: position [m], quaternion (w, x, y, z); the
    simulated drone's truth, else the pose input's latest sample); None outside a hold
    or before a pose."""
    extra = getattr(snap, "extra", None) or {}
    values = extra.get("drone_pose")
    if values is None or len(values) != 7:
        return None
    return Pose.from_arrays(values[:3], values[3:])


class WorldView:
    """World and drone frames in the base frame; ``mount`` is the base in the drone body."""

    def __init__(self, server: viser.ViserServer, mount: Pose) -> None:
        scene = server.scene
        self.mount = mount
        body_in_base = mount.inverse()
        self.drone = scene.add_frame(
            "/drone_frame",
            axes_length=0.08,
            axes_radius=0.0025,
            visible=False,
            position=body_in_base.position,
            wxyz=body_in_base.quaternion,
        )
        self.drone_label = scene.add_label(
            "/drone_frame/label", "drone body", position=(0.0, 0.0, 0.02)
        )
        self.world = scene.add_frame(
            "/world_frame", axes_length=0.15, axes_radius=0.004, visible=False
        )
        self.world_label = scene.add_label("/world_frame/label", "world", position=(0.0, 0.0, 0.03))
        self.active = False

    def update(self, snap: Any) -> None:
        """Show the frames while the loop holds in the world (the snapshot ``snap``'s mode);
        place the world frame where the drone's pose says."""
        self.active = getattr(snap, "mode", "") == HOLD_MODE
        pose = drone_pose(snap) if self.active else None
        self.drone.visible = self.active
        self.world.visible = pose is not None
        if pose is not None:
            world_in_base = (pose @ self.mount).inverse()  # base <- world
            self.world.position = np.asarray(world_in_base.position, dtype=np.float64)
            self.world.wxyz = np.asarray(world_in_base.quaternion, dtype=np.float64)

    def remove(self) -> None:
        for handle in (self.drone, self.world):
            handle.remove()
