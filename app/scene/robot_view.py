"""The robot in the scene: base, servos, links, platform, drawn from the live geometry.

``RobotView`` owns its viser handles like viser's ``ViserUrdf``: build once from the robot's
dimensions (a different geometry in the config draws a different robot), ``update(joints)``
at display rate, ``visible`` toggle, ``remove()``. The same class draws the translucent ghost
of the commanded pose (``ghost=True``), so lag between command and measurement shows.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import viser

from app.control.model import Robot, leg_values
from app.scene.geometry import LEG_ANGLES_RAD, radial, robot_lines
from kinematics import LinearDelta, Tool

LEG_COLOURS = ((222, 76, 64), (64, 168, 90), (60, 112, 214))
GHOST_COLOUR = (175, 180, 190)
HEADING_M = 0.03  # the wrist's heading arrow: its length [m]
SERVO_SIZE_M = (0.0465, 0.034, 0.0285)  # XM430-W210 case: radial, along the shaft, height


def _disc(radius_m: float, corners: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A flat regular polygon in the xy plane, vertices (corners + 1, 3), fan faces."""
    angles = np.linspace(0.0, 2.0 * math.pi, corners, endpoint=False) + math.pi / corners
    rim = np.stack([radius_m * np.cos(angles), radius_m * np.sin(angles), 0 * angles], -1)
    vertices = np.concatenate([np.zeros((1, 3)), rim])
    faces = np.array([[0, 1 + i, 1 + (i + 1) % corners] for i in range(corners)])
    return vertices, faces


def _yaw_wxyz(angle_rad: float) -> tuple[float, float, float, float]:
    """Quaternion (w, x, y, z) of a rotation by ``angle_rad`` about z."""
    return (math.cos(angle_rad / 2), 0.0, 0.0, math.sin(angle_rad / 2))


def segment_colours(colours: tuple, rods: bool) -> np.ndarray:
    """Per-vertex colours for 3 legs x (1 or 2) segments x 2 ends, uint8."""
    per_leg = 2 if rods else 1
    rows = [np.tile(np.asarray(c, np.uint8), (per_leg, 2, 1)) for c in colours]
    return np.concatenate(rows)


class RobotView:
    """Draws one pose of a Delta under ``root`` (e.g. "/robot" or "/ghost")."""

    def __init__(
        self,
        server: viser.ViserServer,
        robot: Robot,
        root: str = "/robot",
        ghost: bool = False,
        tool: Tool | None = None,
    ) -> None:
        self.robot = robot
        self.root = root
        self.ghost = ghost
        self.tool_model = tool if tool is not None and tool.length_m > 0.0 else None
        self.has_wrist = tool is not None and tool.wrist  # the tool turns about z by phi
        self._joints: np.ndarray | None = None
        self._phi = 0.0
        scene = server.scene
        colours = (GHOST_COLOUR,) * 3 if ghost else LEG_COLOURS
        nan = np.zeros((3, 2, 3))
        self.upper = scene.add_line_segments(
            f"{root}/upper",
            nan,
            segment_colours(colours, False),
            thickness=0.006 if ghost else 0.011,
        )
        light = tuple(tuple(int(0.7 * c + 0.3 * 255) for c in col) for col in colours)
        self.rods = scene.add_line_segments(
            f"{root}/rods",
            np.zeros((6, 2, 3)),
            segment_colours(light, True),
            thickness=0.003 if ghost else 0.006,
        )
        r = max(leg_values(robot, "r"))
        disc = _disc(r + 0.012, corners=3 if r < 0.02 else 6)
        self.platform = scene.add_mesh_simple(
            f"{root}/platform",
            disc[0],
            disc[1],
            color=GHOST_COLOUR if ghost else (70, 74, 84),
            side="double",
            opacity=0.35 if ghost else None,
        )
        self.tool = None  # the tool: a segment from the platform centre to the tip
        if self.tool_model is not None:
            self.tool = scene.add_line_segments(
                f"{root}/tool",
                np.zeros((1, 2, 3)),
                np.full((1, 2, 3), 120 if ghost else 230, np.uint8),
                thickness=0.004 if ghost else 0.008,
            )
        self.heading = None  # with a wrist: an arrow along the tool's x axis turned by phi
        if self.has_wrist:
            self.heading = scene.add_line_segments(
                f"{root}/heading",
                np.zeros((3, 2, 3)),
                np.full((3, 2, 3), (150, 150, 150) if ghost else (230, 120, 20), np.uint8),
                thickness=0.003 if ghost else 0.006,
            )
        self.joints = None
        self._static: list[Any] = []
        if not ghost:
            self.joints = scene.add_point_cloud(
                f"{root}/joints",
                np.zeros((9, 3)),
                (40, 42, 48),
                point_size=0.012,
                point_shape="circle",
                precision="float32",
            )
            self._add_base(scene)

    def _add_base(self, scene: Any) -> None:
        """Base plate and servos (rotary) or rails (linear): static, drawn once."""
        robot = self.robot
        vertices, faces = _disc(max(leg_values(robot, "R")) + 0.03)
        self._static.append(
            scene.add_mesh_simple(
                f"{self.root}/base",
                vertices + [0, 0, 0.02],
                faces,
                color=(120, 126, 138),
                side="double",
            )
        )
        if not isinstance(robot, LinearDelta):
            for i, angle in enumerate(LEG_ANGLES_RAD):
                # The shaft sits near the case's outer end, so the case reaches inwards.
                centre = (leg_values(robot, "R")[i] - 0.012) * radial(i) + [0, 0, 0.003]
                self._static.append(
                    scene.add_box(
                        f"{self.root}/servo_{i}",
                        (45, 47, 52),
                        SERVO_SIZE_M,
                        position=centre,
                        wxyz=_yaw_wxyz(angle),
                    )
                )
            return
        half = robot.l + robot.R
        rails = [
            [
                robot.R * radial(i) - half * np.asarray(robot._rail(i)),
                robot.R * radial(i) + half * np.asarray(robot._rail(i)),
            ]
            for i in range(3)
        ]
        self._static.append(
            scene.add_line_segments(
                f"{self.root}/rails", np.asarray(rails), (90, 94, 104), thickness=0.008
            )
        )

    def use_robot(self, robot: Robot) -> None:
        """Draw the links of ``robot`` from now on (the controller's model changed: a
        geometry calibration applied); the next update redraws the pose."""
        self.robot = robot
        self._joints = None

    def update(self, joints: Any, phi_rad: float = 0.0) -> bool:
        """Draw the pose for ``joints`` (3,) [rad or m] and, with a wrist, the wrist angle
        ``phi_rad`` [rad] (the tool turned about z, the heading arrow); False (and nothing
        sent) if both are unchanged by more than 1e-5 or there is no valid FK, so an idle
        robot costs no traffic. Without a wrist phi is ignored (the tool stays at phi = 0)."""
        joints = np.asarray(joints, dtype=np.float64)
        phi = float(phi_rad) if self.has_wrist and math.isfinite(phi_rad) else 0.0
        if not np.isfinite(joints).all():
            return False
        if (
            self._joints is not None
            and np.abs(joints - self._joints).max() < 1e-5
            and abs(phi - self._phi) < 1e-5
        ):
            return False
        lines = robot_lines(self.robot, joints)
        if not np.isfinite(lines.rods).all():
            return False
        self._joints = joints
        self._phi = phi
        self.upper.points = lines.upper
        self.rods.points = lines.rods.reshape(6, 2, 3)
        centre = lines.rods[:, :, 1].mean(axis=(0, 1))
        self.platform.position = centre
        if self.tool is not None and self.tool_model is not None:
            tip = (
                self.tool_model.tip(centre, phi) if self.has_wrist else self.tool_model.tip(centre)
            )
            self.tool.points = np.stack([centre, tip])[None]
        if self.heading is not None:
            self.heading.points = heading_arrow(centre, phi, HEADING_M)
        if self.joints is not None:
            self.joints.points = np.concatenate(
                [lines.upper[:, 0], lines.upper[:, 1], lines.rods[:, :, 1].mean(axis=1)]
            )
        return True

    @property
    def visible(self) -> bool:
        return self.upper.visible

    @visible.setter
    def visible(self, value: bool) -> None:
        for handle in (self.upper, self.rods, self.platform, self.joints, self.tool, self.heading):
            if handle is not None:
                handle.visible = value

    def remove(self) -> None:
        """Remove every handle under this view's root."""
        handles = (
            self.upper,
            self.rods,
            self.platform,
            self.joints,
            self.tool,
            self.heading,
            *self._static,
        )
        for handle in handles:
            if handle is not None:
                handle.remove()


def heading_arrow(centre: Any, phi_rad: float, length_m: float) -> np.ndarray:
    """The wrist's heading as an arrow in the platform's plane: segments (3, 2, 3) [m], the
    shaft from ``centre`` (3,) along (cos phi, sin phi, 0) for ``length_m`` and two barbs
    at its head (the tool's x axis turned by the wrist angle ``phi_rad`` [rad] about z)."""
    centre = np.asarray(centre, dtype=np.float64)
    along = np.array([math.cos(phi_rad), math.sin(phi_rad), 0.0])
    across = np.array([-along[1], along[0], 0.0])
    head = centre + length_m * along
    barb = 0.3 * length_m
    return np.stack(
        [
            [centre, head],
            [head, head - barb * along + 0.6 * barb * across],
            [head, head - barb * along - 0.6 * barb * across],
        ]
    )


def platform_centre(robot: Robot, joints: Any) -> np.ndarray:
    """The platform centre [m] as drawn: mean of the rods' lower ends (= FK point)."""
    return robot_lines(robot, joints).rods[:, :, 1].mean(axis=(0, 1))
