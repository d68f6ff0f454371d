"""Hold-in-world in the scene: the world frame, the drone's frame and the world-fixed goal.

The scene is drawn in the base frame, so while the drone drifts the world frame (and the
goal fixed in it) move and the robot stays put, which is what the servos see. Shown only
while the loop's goal source is the hold-world mode (``app.world.hold.HoldSource``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import viser

from kinematics import Pose

HOLD_MODE = "hold-world"


def drone_pose(source: Any) -> Pose | None:
    """The drone's body-to-world pose the hold source works from, if it can be read
    without side effects: the simulated drone's truth at the source's time, else the
    external tracker's latest sample (never ``provider.observe``, which updates state)."""
    provider = getattr(source, "provider", None)
    if provider is None:
        return None
    pose = provider.true_pose(source.t_s) if hasattr(provider, "true_pose") else None
    tracker = getattr(provider, "tracker", None)
    if pose is None and tracker is not None:
        sample, _ = tracker.latest()
        pose = sample.pose if sample is not None else None
    return pose


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

    def update(self, source: Any) -> None:
        """Show the frames while ``source`` is hold-in-world; place the world frame."""
        self.active = getattr(source, "name", "") == HOLD_MODE
        pose = drone_pose(source) if self.active else None
        self.drone.visible = self.active
        self.world.visible = pose is not None
        if pose is not None:
            world_in_base = (pose @ self.mount).inverse()  # base <- world
            self.world.position = np.asarray(world_in_base.position, dtype=np.float64)
            self.world.wxyz = np.asarray(world_in_base.quaternion, dtype=np.float64)

    def remove(self) -> None:
        for handle in (self.drone, self.world):
            handle.remove()
