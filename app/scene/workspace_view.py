"""The workspace in the scene: each leg's torus (thesis Fig. 4.2) and the reachable volume.

The tori are drawn as their lower halves (the platform never goes above the base, thesis
ch. 4.1), translucent, in each leg's colour; the reachable volume is the gate's own
workspace (margin and ceiling from the config), so what the operator sees is exactly where
jog goals are clamped to. Both are static: built once, toggled, removed (and built again
by the scene when a calibration changes the controller's robot model).
"""

from __future__ import annotations

import viser

from app.control.model import Robot
from app.scene.geometry import torus_mesh
from app.scene.robot_view import LEG_COLOURS
from app.scene.volume import VolumeMesh, reachable_volume

VOLUME_COLOUR = (110, 190, 230)


class WorkspaceView:
    """Tori and reachable volume of ``robot`` under ``root``; ``margin_m`` and ``z_max_m``
    are the gate's (LimitSettings.workspace_margin_m, z_max_m) [m]. The volume is where
    the tool tip may go: the platform's, moved by ``tool_offset_m`` (3,) [m] (phi = 0)."""

    def __init__(
        self,
        server: viser.ViserServer,
        robot: Robot,
        margin_m: float,
        z_max_m: float,
        root: str = "/workspace",
        tool_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        scene = server.scene
        self.tori = []
        for leg in range(3):
            vertices, faces = torus_mesh(robot, leg)
            self.tori.append(
                scene.add_mesh_simple(
                    f"{root}/torus_{leg}",
                    vertices,
                    faces,
                    color=LEG_COLOURS[leg],
                    opacity=0.08,
                    side="double",
                    cast_shadow=False,
                    receive_shadow=False,
                )
            )
        self.mesh: VolumeMesh = reachable_volume(robot, margin_m, z_max_m)
        self.volume = scene.add_mesh_simple(
            f"{root}/volume",
            self.mesh.vertices,
            self.mesh.faces,
            color=VOLUME_COLOUR,
            opacity=0.3,
            side="double",
            cast_shadow=False,
            receive_shadow=False,
            position=tool_offset_m,
        )

    @property
    def tori_visible(self) -> bool:
        return self.tori[0].visible

    @tori_visible.setter
    def tori_visible(self, value: bool) -> None:
        for handle in self.tori:
            handle.visible = value

    @property
    def volume_visible(self) -> bool:
        return self.volume.visible

    @volume_visible.setter
    def volume_visible(self, value: bool) -> None:
        self.volume.visible = value

    def remove(self) -> None:
        for handle in (*self.tori, self.volume):
            handle.remove()
