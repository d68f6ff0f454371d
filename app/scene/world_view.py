"""Hold-in-world in the scene: the world frame, the drone's frame and the world-fixed goal.

The scene is drawn in the base frame, so while the drone drifts the world frame (and the
goal fixed in it) move and the robot stays put, which is what the servos see. Shown while
the loop holds in the world (mode ``hold-world``, app/world/hold.py: the pose the hold
works from) and, outside a hold, while a pose input is live (its latest sample, fresh or
stale; the drone's label says which): the drone's pose drawn as where the world lies.
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


LIVE_STATES = ("ok", "stale")  # a pose input shown outside a hold: fresh, or stale (said)


def live_pose(pose_input: Any) -> tuple[Pose, str] | None:
    """(the drone's pose, the input's state) from a pose input's status ``pose_input``
    (GET /api/mav/pose's fields: ``state``, ``position_m`` [m], ``quaternion``) while it is
    live (ok or stale); None otherwise (no input, none yet, lost)."""
    if not isinstance(pose_input, dict) or pose_input.get("state") not in LIVE_STATES:
        return None
    position, quaternion = pose_input.get("position_m"), pose_input.get("quaternion")
    if position is None or quaternion is None:
        return None
    return Pose.from_arrays(position, quaternion), str(pose_input["state"])


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

    def update(self, snap: Any, pose_input: Any = None) -> None:
        """Show the frames while the loop holds in the world (the snapshot ``snap``'s mode)
        or, outside a hold, while the pose input ``pose_input`` (its status: ``live_pose``)
        is live; place the world frame where the drone's pose says."""
        self.active = getattr(snap, "mode", "") == HOLD_MODE
        pose = drone_pose(snap) if self.active else None
        label = "drone body"
        if not self.active:
            live = live_pose(pose_input)
            if live is not None:
                pose, state = live
                label = "drone (pose input)" if state == "ok" else "drone (pose STALE)"
        self.drone.visible = self.active or pose is not None
        self.world.visible = pose is not None
        if self.drone_label.text != label:
            self.drone_label.text = label
        if pose is not None:
            world_in_base = (pose @ self.mount).inverse()  # base <- world
            self.world.position = np.asarray(world_in_base.position, dtype=np.float64)
            self.world.wxyz = np.asarray(world_in_base.quaternion, dtype=np.float64)

    def remove(self) -> None:
        for handle in (self.drone, self.world):
            handle.remove()
